"""The `--against` shift test's p-values on unchanged sensors: uniform, or a bias?

    python -m benchmarks.blind.gen2.shift_pvalues --out OUT [--out OUT2 ...] [--json F]

Reads the cases of ``benchmarks.blind.gen2.run --only unchanged`` runs (``OUT/cases``,
``OUT/given``, ``OUT/keys``), calibrates the given recording as the run does
(``fit_campaign``) and runs the coefficient-shift test alone (``diagnose_against`` with
``refit=False``: the family p does not depend on the refit diagnosis). For each case: the
family p (Holm over the coefficients; the verdict compares it with α/2 when the refit
diagnosis runs), every coefficient's z, the two χ²/dof (the given model's joint fit, the
re-measurement after the shift) and the family p again with the given model's stderr not
scaled below its information bound (stderr / √min(χ²/dof, 1)).

``--noise-free --realdata DIR``: each pair is simulated again from its key's seed with no
noise (no sensor noise, bench disturbance, placement scatter, output or temperature
quantisation; the same sensor, protocols, timeline and die), its readings put in place of
the noisy ones (the recordings' ``sd_*`` kept, so the fits weigh as the test does), and the
shift fitted again: its z (over the noisy test's σ) is what the protocols alone give an
unchanged sensor, the bias of the test (0 for a model that holds the sensor exactly).
``--channel-noise``: the same with the recordings' own temperature channel kept (its
noise and 0.1 °C codes: the conditioning then works on what it works on in the test).

``--replicate CASE --n N --realdata DIR``: the case's pair (same sensor, protocols,
timeline) recorded N times with fresh noise (the generator's, other seeds), the whole test
run on each: the spread of each coefficient's z (1 for a calibrated σ) and the family p's
shares, for that one protocol pair (``--quiet-temperature``: the temperature channel without
noise or quantisation, so the accelerometer's noise alone).

``--levels L1,L2,..``: no diagnosis; the shift's Holm decision taken again at each level
from the coefficients' z in ``OUT/diagnoses.json`` (a run's, refit diagnosis included):
unchanged sensors given a shift, re-mounts named right (ψ, no bias: score.py's rule) and
the re-mounts' |z| of ψ (a shift detectable at a stricter level scales with its threshold).

Prints the p-values' distribution against uniform (shares at or below 0.0025, 0.005, 0.05,
0.2 with 95 % Clopper–Pearson intervals; the Kolmogorov–Smirnov distance), overall and by
the re-measurement's protocol (kind, schedule, soak), and the coefficients' z spread
(the variance of z, which is 1 for a calibrated σ) by power of temperature and parameter.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.twin_file import Twin
from calibration.recording import read_recording
from calibration.thermal import fit_campaign

LEVELS = (0.0025, 0.005, 0.05, 0.2)


def one_case(out: Path, case: str, key: dict[str, Any]) -> dict[str, Any]:
    fit = fit_campaign(read_recording(out / "given" / f"{case}.csv"))
    model = fit.model
    chi2_given = float(((fit.report or {}).get("joint_fit") or {}).get("chi2_red", np.nan))
    rec = read_recording(out / "cases" / f"{case}.csv")
    d = diagnose_against(rec, Twin(model), refit=False, seed=int(case))
    sh = d.shift
    row: dict[str, Any] = {
        "case": case, "seed_dir": str(out.name), "protocol": key.get("protocol"),
        "given_protocol": key.get("given_protocol"), "p_family": sh.get("p_family"),
        "chi2_given": chi2_given, "chi2_after_shift": sh.get("chi2_per_dof_after_shift"),
        "z": {f"{c['parameter']}^{c['power']}": c["z"] for c in sh.get("coefficients", [])},
        "named": sorted(sh.get("parameters", {})),
    }
    if model.coeff_stderr is not None and np.isfinite(chi2_given) and chi2_given < 1.0:
        floored = replace(model, coeff_stderr=model.coeff_stderr / np.sqrt(chi2_given))
        d2 = diagnose_against(rec, Twin(floored), refit=False, seed=int(case))
        row["p_family_given_floor"] = d2.shift.get("p_family")
    else:
        row["p_family_given_floor"] = row["p_family"]
    return row


def _draws(key: dict[str, Any]):
    """Sensor, given protocol, re-measurement protocol, pattern: as ``_build_against``."""
    from benchmarks.blind.gen2 import effects as fx
    from benchmarks.blind.gen2.protocol import draw_protocol
    from benchmarks.blind.gen2.sensor import draw_sensor

    rng = np.random.default_rng(key["seed"])
    sensor = draw_sensor(rng)
    cal = draw_protocol(rng, kind="updown", schedule="dense24", columns=("sensor_c",),
                        soak_min=20.0)
    again = draw_protocol(rng, kind=str(rng.choice(["oneway", "staircase_down", "sparse"])),
                          columns=("sensor_c",))
    return sensor, cal, again, fx.pattern(rng, 3, 10)


def replicate(key: dict[str, Any], pools, n: int, quiet_temperature: bool = False
              ) -> list[dict[str, Any]]:
    """The case's pair recorded ``n`` times with other noise; the shift test on each.
    ``quiet_temperature``: the sensor_c channel without noise or quantisation (the
    accelerometer's noise alone)."""
    from benchmarks.blind.gen2 import simulate as sim
    from calibration.recording import Recording

    sensor, cal, again, pat = _draws(key)
    if quiet_temperature:
        cal, again = (replace(p, sensor_c_sd_c=0.0, sensor_c_lsb_c=1e-9) for p in (cal, again))
    orig = sim.scene
    out = []
    try:
        for i in range(n):
            for proto, seed, slot in ((cal, key["seed"], "g"), (again, key["seed"] + 7, "c")):
                # the scene (timeline, order of positions) of the case; the noise of seed 10⁹+i
                sim.scene = (lambda p, e, m, pt, _s, tau=None, _seed=seed:
                             orig(p, e, m, pt, _seed, tau))
                cols = sim.record(proto, sensor, pools, None, 0.0, pat,
                                  10**9 + 1000 * i + (slot == "c"))
                if slot == "g":
                    given = Recording.from_columns(cols)
                else:
                    rec = Recording.from_columns(cols)
            fit = fit_campaign(given)
            model = fit.model
            d = diagnose_against(rec, Twin(model), refit=False)
            chi2 = float(((fit.report or {}).get("joint_fit") or {}).get("chi2_red", np.nan))
            p_floor = d.shift.get("p_family")
            if model.coeff_stderr is not None and np.isfinite(chi2) and chi2 < 1.0:
                floored = replace(model, coeff_stderr=model.coeff_stderr / np.sqrt(chi2))
                p_floor = diagnose_against(rec, Twin(floored), refit=False).shift.get(
                    "p_family")
            out.append({"p_family": d.shift.get("p_family"), "p_family_given_floor": p_floor,
                        "chi2_given": chi2,
                        "z": {f"{c['parameter']}^{c['power']}": c["z"]
                              for c in d.shift.get("coefficients", [])}})
    finally:
        sim.scene = orig
    return out


def noise_free_pair(key: dict[str, Any], pools) -> tuple[dict, dict]:
    """The given and re-measured recordings' noise-free readings and die temperatures,
    drawn as ``generate._build_against`` draws them (same seed, same order of draws)."""
    from benchmarks.blind.gen2 import simulate as sim

    sensor, cal, again, pat = _draws(key)

    def quiet(p):
        return replace(p, sensor_noise_g=0.0, vib_sd_g=tuple(0.0 for _ in p.vib_sd_g),
                       placement_rad=0.0, sensor_c_sd_c=0.0, sensor_c_lsb_c=1e-9)

    lsb = sim.LSB_G
    sim.LSB_G = 1e-15  # no output quantisation (a noise-free constant would not dither)
    try:
        g = sim.record(quiet(cal), sensor, pools, None, 0.0, pat, key["seed"])
        c = sim.record(quiet(again), sensor, pools, None, 0.0, pat, key["seed"] + 7)
    finally:
        sim.LSB_G = lsb
    return g, c


def with_readings(rec, cols: dict, temperature: bool = True):
    """``rec`` with the noise-free readings (and temperature) of ``cols`` (rows in order)."""
    from calibration.recording import Recording

    new = dict(rec.columns)
    if len(cols["ax"]) != len(rec):
        raise ValueError("noise-free rows do not match the recording's")
    for k in ("ax", "ay", "az") + (("sensor_c",) if temperature else ()):
        new[k] = np.asarray(cols[k], float)
    out = Recording.from_columns(new)
    out.path = rec.path
    return out


def noise_free_z(out: Path, case: str, key: dict[str, Any], pools,
                 channel_noise: bool = False) -> dict[str, Any]:
    """The shift's z on the noise-free pair, over the noisy test's σ. ``channel_noise``:
    the recordings' own temperature channel (its noise and 0.1 °C codes) kept."""
    from calibration.discrepancy import against as ag

    given = read_recording(out / "given" / f"{case}.csv")
    rec = read_recording(out / "cases" / f"{case}.csv")
    g_nf, c_nf = noise_free_pair(key, pools)
    model = fit_campaign(given).model
    model_nf = fit_campaign(with_readings(given, g_nf, not channel_noise)).model
    rec_nf = with_readings(rec, c_nf, not channel_noise)
    steps = rec.steps()
    temp = ag._temperature(rec, model, [])
    sig = ag._sigma_g(rec, steps, model, rec.raw_g, temp, "reference")
    fitted = ag._fitted_mask(model, "reference", temp, steps)
    noisy = ag.fit_shift(model, rec.raw_g, rec.ref_g, temp, sig, fitted)
    temp_nf = ag._temperature(rec_nf, model_nf, [])
    nf = ag.fit_shift(model_nf, rec_nf.raw_g, rec_nf.ref_g, temp_nf, sig, fitted)
    sd = np.sqrt(noisy.sd_recording**2 + noisy.sd_given**2)
    from calibration import sfem

    # Where the noisy test's δ came from: the re-measurement's noise alone (the noisy
    # recording against the noise-free model) and the given recording's alone.
    rec_noise = ag.fit_shift(model_nf, rec.raw_g, rec.ref_g, temp, sig, fitted)
    giv_noise = ag.fit_shift(model, rec_nf.raw_g, rec_nf.ref_g, temp_nf, sig, fitted)

    def zs(f) -> dict[str, float]:
        return {f"{sfem.PARAM_NAMES[k]}^{j}": round(float(f.delta[k, j] / sd[k, j]), 3)
                for k, j in np.argwhere(fitted) if sd[k, j] > 0}

    z = zs(nf)
    return {"case": case, "protocol": key.get("protocol"), "z_bias": z,
            "z_noisy": zs(noisy), "z_recording_noise": zs(rec_noise),
            "z_given_noise": zs(giv_noise),
            "max_abs_z_bias": max((abs(v) for v in z.values()), default=0.0),
            "rms_given_nf_ug": round(float(np.sqrt(np.mean(ag._residual(
                model_nf.coeffs, model_nf, rec_nf.raw_g, rec_nf.ref_g, temp_nf) ** 2)) * 1e6),
                3)}


def ks_uniform(p: np.ndarray) -> float:
    """Kolmogorov–Smirnov distance of ``p`` from the uniform on [0, 1]."""
    p = np.sort(np.asarray(p, float))
    n = p.size
    if n == 0:
        return float("nan")
    i = np.arange(1, n + 1)
    return float(max(np.max(i / n - p), np.max(p - (i - 1) / n)))


def describe(p: list[float]) -> dict[str, Any]:
    a = np.asarray(p, float)
    out: dict[str, Any] = {"n": int(a.size), "ks": round(ks_uniform(a), 4)}
    for lev in LEVELS:
        k = int(np.sum(a <= lev))
        lo, hi = clopper_pearson(k, a.size)
        out[f"<={lev:g}"] = [k, round(100 * k / max(a.size, 1), 2),
                             round(100 * lo, 2), round(100 * hi, 2)]
    return out


def groups(rows: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    g: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        kind, sched, _cols, soak = (r["protocol"] or "?/?/?/?").split("/")
        g[f"kind={kind}"].append(r)
        g[f"schedule={sched}"].append(r)
        g[f"soak={soak}"].append(r)
    return dict(sorted(g.items()))


def coefficient_p(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Each coefficient's own two-sided p (uniform if its σ is calibrated), pooled over the
    cases and coefficients (correlated within a case): shares and the KS distance."""
    from scipy import stats as sps

    z = np.array([v for r in rows for v in r["z"].values()], float)
    p = 2.0 * sps.norm.sf(np.abs(z))
    out: dict[str, Any] = {"n": int(p.size), "ks": round(ks_uniform(p), 4)}
    for lev in (1e-4, 1e-3, 0.01, 0.05, 0.2):
        out[f"<={lev:g}"] = [int(np.sum(p <= lev)), round(float(np.mean(p <= lev)) / lev, 2)]
    out["columns"] = "[count, share / level (1 if calibrated)]"
    return out


def z_spread(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Variance of the coefficients' z (1 for a calibrated σ), by power and by parameter."""
    by_pow: dict[str, list[float]] = defaultdict(list)
    by_par: dict[str, list[float]] = defaultdict(list)
    for r in rows:
        for name, z in r["z"].items():
            par, pw = name.split("^")
            by_pow[f"T^{pw}"].append(z)
            by_par[par].append(z)

    def v(zs: list[float]) -> list[float]:
        a = np.asarray(zs, float)
        return [round(float(np.mean(a**2)), 3), round(float(np.mean(np.abs(a) > 3.0)) * 1e3, 2),
                int(a.size)]

    return {"by_power": {k: v(z) for k, z in sorted(by_pow.items())},
            "by_parameter": {k: v(z) for k, z in sorted(by_par.items())},
            "columns": ["mean z² (1 if calibrated)", "per mille |z| > 3 (2.7 if normal)", "n"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, action="append", default=[])
    ap.add_argument("--json", type=Path, default=None, help="write every case's row here")
    ap.add_argument("--noise-free", action="store_true",
                    help="the shift's z on each pair simulated again without noise (the bias)")
    ap.add_argument("--realdata", default=None, help="the shared real recordings (noise-free)")
    ap.add_argument("--channel-noise", action="store_true",
                    help="--noise-free with the recordings' own temperature channel kept")
    ap.add_argument("--cases", default=None, help="comma list of cases (noise-free only)")
    ap.add_argument("--replicate", default=None, help="one case: its pair with fresh noise")
    ap.add_argument("--n", type=int, default=100, help="replicates (--replicate)")
    ap.add_argument("--quiet-temperature", action="store_true",
                    help="--replicate with a noise-free, unquantised sensor_c channel")
    ap.add_argument("--levels", default=None, help="the shift's Holm at these levels "
                    "(from OUT/diagnoses.json, no diagnosis)")
    ap.add_argument("--rows", type=Path, action="append", default=None,
                    help="summarise these --json files' rows again (no diagnosis)")
    a = ap.parse_args(argv)
    if a.levels:
        return _levels_main(a)
    if a.replicate:
        return _replicate_main(a)
    if a.noise_free:
        return _noise_free_main(a)
    rows = []
    for f in a.rows or []:
        rows += json.loads(f.read_text())["rows"]
    for out in [] if a.rows else a.out:
        keys = {p.stem: json.loads(p.read_text()) for p in (out / "keys").glob("*.json")}
        cases = sorted(c for c, k in keys.items() if k.get("change") == "unchanged")
        for i, c in enumerate(cases, 1):
            rows.append(one_case(out, c, keys[c]))
            if i % 50 == 0:
                print(f"  {out.name}: {i}/{len(cases)}", file=sys.stderr)
    res = {"all": describe([r["p_family"] for r in rows]),
           "all, given stderr not below its information bound": describe(
               [r["p_family_given_floor"] for r in rows]),
           "by protocol": {k: describe([r["p_family"] for r in v])
                           for k, v in groups(rows).items()},
           "z": z_spread(rows), "coefficient p": coefficient_p(rows),
           "chi2_given": [round(float(q), 3) for q in np.nanpercentile(
               [r["chi2_given"] for r in rows], [10, 50, 90])],
           "smallest": sorted(({"case": r["case"], "dir": r["seed_dir"],
                                "protocol": r["protocol"], "p_family": r["p_family"],
                                "p_given_floor": r["p_family_given_floor"],
                                "named": r["named"], "chi2_given": r["chi2_given"]}
                               for r in rows), key=lambda r: r["p_family"])[:8]}
    if a.json:
        a.json.write_text(json.dumps({"summary": res, "rows": rows}, indent=1))
    print(json.dumps(res, indent=1))
    return 0


def holm_named(z: dict[str, float], level: float) -> list[str]:
    """Coefficients Holm's step-down names at ``level`` (two-sided normal p of each z)."""
    from scipy import stats as sps

    if not z:
        return []
    names = list(z)
    logp = np.log(2.0) + sps.norm.logsf(np.abs(np.array([z[n] for n in names], float)))
    m = len(names)
    order = np.argsort(logp)
    holm = np.maximum.accumulate(np.minimum(logp[order] + np.log(m - np.arange(m)), 0.0))
    keep = np.cumprod(holm < np.log(level)).astype(bool)
    return [names[i] for i, k in zip(order, keep, strict=True) if k]


def _levels_main(a: argparse.Namespace) -> int:
    levels = [float(x) for x in a.levels.split(",")]
    res: dict[str, Any] = {}
    zpsi = []
    for out in a.out:
        diags = json.loads((out / "diagnoses.json").read_text())
        keys = {p.stem: json.loads(p.read_text()) for p in (out / "keys").glob("*.json")}
        for lev in levels:
            r = res.setdefault(f"{lev:g}", {"unchanged": 0, "unchanged_shift": 0,
                                            "remount": 0, "remount_right": 0})
            for c, k in keys.items():
                if k.get("kind") != "against" or c not in diags:
                    continue
                z = {f"{x['parameter']}^{x['power']}": x["z"] for x in
                     (diags[c].get("parameter_shift") or {}).get("coefficients", [])}
                named = holm_named(z, lev)
                if k["change"] == "unchanged":
                    r["unchanged"] += 1
                    r["unchanged_shift"] += bool(named)
                else:
                    r["remount"] += 1
                    r["remount_right"] += bool(named) and any(n.startswith("mz^") for n in
                                                              named) and not any(
                        n.startswith(("bx^", "by^", "bz^")) for n in named)
                    if lev == levels[0]:
                        zpsi.append(abs(z.get("mz^0", 0.0)))
    res["remount |z| of psi (mz^0): min, median"] = (
        [round(float(np.min(zpsi)), 1), round(float(np.median(zpsi)), 1)] if zpsi else [])
    print(json.dumps(res, indent=1))
    return 0


def _replicate_main(a: argparse.Namespace) -> int:
    from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir

    pools = load_pools(realdata_dir(a.realdata))
    key = json.loads((a.out[0] / "keys" / f"{a.replicate}.json").read_text())
    rows = replicate(key, pools, a.n, a.quiet_temperature)
    res = {"case": a.replicate, "protocol": key.get("protocol"),
           "quiet_temperature": a.quiet_temperature,
           "p_family": describe([r["p_family"] for r in rows]),
           "p_family, given stderr not below its information bound": describe(
               [r.get("p_family_given_floor", r["p_family"]) for r in rows]),
           "z": z_spread(rows), "coefficient p": coefficient_p(rows)}
    if a.json:
        a.json.write_text(json.dumps({"summary": res, "rows": rows}, indent=1))
    print(json.dumps(res, indent=1))
    return 0


def _noise_free_main(a: argparse.Namespace) -> int:
    from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir

    pools = load_pools(realdata_dir(a.realdata))
    rows = []
    for out in a.out:
        keys = {p.stem: json.loads(p.read_text()) for p in (out / "keys").glob("*.json")}
        cases = sorted(c for c, k in keys.items() if k.get("change") == "unchanged")
        if a.cases:
            cases = [c for c in cases if c in set(a.cases.split(","))]
        for i, c in enumerate(cases, 1):
            rows.append(noise_free_z(out, c, keys[c], pools, a.channel_noise))
            if i % 50 == 0:
                print(f"  {out.name}: {i}/{len(cases)}", file=sys.stderr)
    allz = np.array([v for r in rows for v in r["z_bias"].values()], float)
    res = {"n": len(rows), "coefficients": int(allz.size),
           "abs_z_bias_percentiles_50_90_99_max": [round(float(q), 3) for q in np.percentile(
               np.abs(allz), [50, 90, 99, 100])] if allz.size else [],
           "cases_max_abs_z_bias_over_1": sum(r["max_abs_z_bias"] > 1 for r in rows),
           "largest": sorted(({"case": r["case"], "protocol": r["protocol"],
                               "max_abs_z_bias": r["max_abs_z_bias"],
                               "rms_given_nf_ug": r["rms_given_nf_ug"]} for r in rows),
                             key=lambda r: -r["max_abs_z_bias"])[:6]}
    if a.json:
        a.json.write_text(json.dumps({"summary": res, "rows": rows}, indent=1))
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
