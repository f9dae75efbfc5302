"""Where a soak policy's held-out loss comes from: per step, per held-out temperature (issue 12).

Reads the campaigns ``bench_throughput.py --dump DIR`` wrote (each sensor's stored rows
and the campaign's k̂) and, for one policy against the fixed hour of the same noise draw,
per sensor:

* **held-out per temperature**: the refitted model's held-out rms at each held-out die
  temperature (``bench_soak_time.heldout_errors_g``: 60 directions, between the setpoints),
  policy against fixed hour;
* **substitution per step**: the fixed hour's rows with step s replaced by the policy's
  (same positions, same noise: the bench keys a capture's noise by what it measures), refitted;
  the change of the held-out sum of squares is what step s's soak costs on its own;
* **soak-only**: the same campaigns refitted with every row's output replaced by its
  capture's noise-free mean (``BenchTruth.noise_free_log``: the die temperature, its rate and
  the temperature channel as they were, the accelerometer noise gone): the held-out error
  the soak alone leaves, per held-out temperature; the substitution per step on those rows;
  and each step's row errors (the rate-corrected row less the true sensor at the row's
  conditioned die temperature): |mean| over the positions (common to the step) and the
  rms about it (varying), µg;
* **expected ratio**: with the noise n and a policy's soak-induced error s, a held-out
  sum of squares is |n|² + 2 n·s + |s|²; the cross term has mean 0 over noise draws but
  its sign is the draw's, and it is what makes one draw's per-sensor ratio scatter. The
  expected ratio replaces it by its mean: √((N + S_policy) / (N + S_fixed)), N the fixed
  hour's sum of squares less its soak-only part, per draw.

Both campaigns are refitted the way the engine fits them (``fit_campaign`` with the k̂ the
campaign's fit used, none for the fixed hour), so the totals reproduce the bench's figures.

Usage: .venv/bin/python benchmarks/bench_heldout_steps.py DIR [--sensors SN-T0006,…]
                                                          [--policy "measured k, corrected"]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.bench_soak_time import heldout_errors_g, make_truth  # noqa: E402
from benchmarks.bench_throughput import POLICIES, dump_name, rate_of  # noqa: E402
from calibration.recording import Recording  # noqa: E402
from calibration.thermal import fit_campaign  # noqa: E402
from service.demo import SETPOINTS_C  # noqa: E402
from service.engine import rate_gain  # noqa: E402

HELDOUT_C = np.arange(SETPOINTS_C[0] + 5.0, SETPOINTS_C[-1], 10.0)
N_DIRECTIONS = 60  # heldout_errors_g's sphere


def correction_gain(k_hat: Any) -> np.ndarray | None:
    """The k̂ the campaign's fit subtracted (``rate_gain.correction_gain_ug_per_c_per_min``)."""
    if not k_hat:
        return None
    gain, sd = (np.asarray(v, float) for v in k_hat)
    est = rate_gain.RateGain(gain, sd, 0, 0)
    return rate_gain.correction_gain_ug_per_c_per_min(est)


def refit(columns: dict[str, list[float]], k: np.ndarray | None) -> Any:
    rec = Recording.from_columns(
        {n: np.asarray(v, float) for n, v in columns.items()}, path="<dump>"
    )
    return fit_campaign(rec, rate_gain_ug_per_c_per_min=k)


def heldout_by_temp_sq(fit: Any, truth: Any) -> np.ndarray:
    """Sum of squared held-out errors (g²) at each held-out temperature."""
    err = heldout_errors_g(fit.model, truth, HELDOUT_C).reshape(HELDOUT_C.size, N_DIRECTIONS)
    return np.sum(err**2, axis=1)


def splice(
    base: dict[str, list[float]], other: dict[str, list[float]], step: int
) -> dict[str, list[float]]:
    """``base``'s rows with those of ``step`` taken from ``other`` (time order kept)."""
    b_step, o_step = np.asarray(base["step"]), np.asarray(other["step"])
    keep_b, keep_o = np.flatnonzero(b_step != step), np.flatnonzero(o_step == step)
    rows = [(base["t_s"][i], "b", i) for i in keep_b] + [(other["t_s"][i], "o", i) for i in keep_o]
    rows.sort()
    return {n: [(base if src == "b" else other)[n][i] for _, src, i in rows] for n in base}


def row_errors_g(fit: Any, columns: dict[str, list[float]], truth: Any) -> dict[tuple, np.ndarray]:
    """(step, reference, visit) → the row's error the fit sees (raw used − truth at the row's
    conditioned die temperature), g; accelerometer noise included.

    Keyed as the bench keys a capture's noise (``BenchTruth._capture_key``): Table 1 has
    positions with the same reference (rotations about gravity), which share a noise stream
    taken in visit order, so the k-th visit of a reference in a step is what pairs."""
    raw = (
        fit.raw_used_g
        if fit.raw_used_g is not None
        else np.column_stack([columns["ax"], columns["ay"], columns["az"]])
    )
    ref = np.column_stack([columns["ref_x"], columns["ref_y"], columns["ref_z"]])
    die_c = np.asarray(fit.row_temperature_c, float) - truth.temp_offset_c
    err = np.asarray(raw, float) - truth.ideal_raw_g(ref, die_c)
    out: dict[tuple, np.ndarray] = {}
    seen: dict[tuple, int] = {}
    for i in np.argsort(np.asarray(columns["t_s"]), kind="stable"):
        where = (int(columns["step"][i]), *(int(round(v * 100.0)) for v in ref[i]))
        seen[where] = seen.get(where, -1) + 1
        out[(*where, seen[where])] = err[i]
    return out


def noise_free_columns(
    columns: dict[str, list[float]], log: list[tuple[list[int], list[float]]]
) -> dict[str, list[float]] | None:
    """``columns`` with each row's output replaced by its capture's noise-free mean
    (``BenchTruth.noise_free_log``): what the row would read without the accelerometer
    noise, the die temperature and rate (and the temperature channel) as they were."""
    by_key: dict[tuple, list[list[float]]] = {}
    for key, ideal in log:
        by_key.setdefault(tuple(key[1:5]), []).append(ideal)  # pose, setpoint; attempts in order
    order = np.argsort(np.asarray(columns["t_s"]), kind="stable")
    rows: dict[tuple, list[int]] = {}
    for i in order:
        ref = (columns["ref_x"][i], columns["ref_y"][i], columns["ref_z"][i])
        where = (
            *(int(round(v * 100.0)) + 200 for v in ref),
            int(round(columns["setpoint_c"][i])) + 1000,
        )
        rows.setdefault(where, []).append(int(i))
    out = {n: list(v) for n, v in columns.items()}
    for where, idx in rows.items():
        caps = by_key.get(where, [])
        if len(caps) < len(idx):
            return None
        # a quality re-measure stores the later capture: the last len(idx) attempts
        for i, ideal in zip(idx, caps[len(caps) - len(idx) :], strict=True):
            out["ax"][i], out["ay"][i], out["az"][i] = ideal
    return out


def with_noise(columns: dict[str, list[float]], sd_g: float, draw: int) -> dict[str, list[float]]:
    """Noise-free ``columns`` plus a fresh accelerometer noise draw (sd/√n per row and axis),
    keyed like the bench's captures (step, reference, visit): two campaigns get the same
    noise at the same measurement, whatever their order and timing."""
    out = {n: list(v) for n, v in columns.items()}
    seen: dict[tuple, int] = {}
    for i in np.argsort(np.asarray(columns["t_s"]), kind="stable"):
        ref = (columns["ref_x"][i], columns["ref_y"][i], columns["ref_z"][i])
        where = (int(columns["step"][i]), *(int(round(v * 100.0)) + 200 for v in ref))
        seen[where] = seen.get(where, -1) + 1
        rng = np.random.default_rng([draw, *where, seen[where], 11])
        noise = rng.normal(0.0, sd_g / math.sqrt(max(columns["n"][i], 1.0)), 3)
        for axis, v in zip(("ax", "ay", "az"), noise, strict=True):
            out[axis][i] += float(v)
    return out


def analyse(dump_dir: Path, policy: str, sensors: list[str] | None, mc: int = 0) -> None:
    draws = sorted(
        int(p.stem.rsplit("draw", 1)[1])
        for p in dump_dir.glob(f"{dump_name(POLICIES[0], 0).rsplit('-draw', 1)[0]}-draw*.json")
    )
    per_sensor: dict[str, dict[str, Any]] = {}
    for d in draws:
        path = dump_dir / dump_name(policy, d)
        if not path.exists():
            continue
        fixed = json.loads((dump_dir / dump_name(POLICIES[0], d)).read_text())
        pol = json.loads(path.read_text())
        rates = fixed["rates"]
        for serial in sensors or sorted(fixed["sensors"]):
            if serial not in fixed["sensors"] or serial not in pol["sensors"]:
                continue
            idx = fixed["sensors"][serial]["index"]
            truth = make_truth(idx + 1, False, rate_of(idx, rates))
            cf = fixed["sensors"][serial]["columns"]
            cp = pol["sensors"][serial]["columns"]
            kp = correction_gain(pol["sensors"][serial]["k_hat"])
            sq_f = heldout_by_temp_sq(refit(cf, None), truth)
            sq_p = heldout_by_temp_sq(refit(cp, kp), truth)
            nf_f = noise_free_columns(cf, fixed["sensors"][serial].get("noise_free") or [])
            nf_p = noise_free_columns(cp, pol["sensors"][serial].get("noise_free") or [])
            if nf_f is None or nf_p is None:
                raise SystemExit(f"{path}: no noise-free log for {serial} (re-run the bench)")
            fit_nf_f, fit_nf_p = refit(nf_f, None), refit(nf_p, kp)
            s_f, s_p = heldout_by_temp_sq(fit_nf_f, truth), heldout_by_temp_sq(fit_nf_p, truth)
            steps = sorted(set(int(s) for s in cf["step"]))
            # What one step's soak costs on its own, without noise: the fixed hour's rows with
            # that step's taken from the policy, fitted with the policy's k̂ (the fixed hour's
            # rows barely move with it: their die is at rest).
            base = float(np.sum(heldout_by_temp_sq(refit(nf_f, kp), truth)))
            subst = [
                float(np.sum(heldout_by_temp_sq(refit(splice(nf_f, nf_p, s), kp), truth))) - base
                for s in steps
            ]
            # The expected held-out sum of squares of each campaign's own design (its steps'
            # and rows' temperatures): ``mc`` fresh noise draws on its noise-free rows, the
            # same draws for both campaigns.
            mc_f, mc_p = [], []
            for j in range(mc):
                noisy_f = with_noise(nf_f, truth.sample_sd_g(), 1000 * d + j)
                noisy_p = with_noise(nf_p, truth.sample_sd_g(), 1000 * d + j)
                mc_f.append(float(np.sum(heldout_by_temp_sq(refit(noisy_f, None), truth))))
                mc_p.append(float(np.sum(heldout_by_temp_sq(refit(noisy_p, kp), truth))))
            ef, ep = row_errors_g(fit_nf_f, nf_f, truth), row_errors_g(fit_nf_p, nf_p, truth)
            rows_f, rows_p = [], []
            for s in steps:
                rows_f.append(step_row_error_ug(ef, s))
                rows_p.append(step_row_error_ug(ep, s))
            acc = per_sensor.setdefault(
                serial,
                {
                    "sq_f": np.zeros_like(sq_f),
                    "sq_p": np.zeros_like(sq_p),
                    "draws": 0,
                    "s_f": np.zeros_like(sq_f),
                    "s_p": np.zeros_like(sq_f),
                    "subst": np.zeros(len(steps)),
                    "rows_f": np.zeros((len(steps), 2)),
                    "rows_p": np.zeros((len(steps), 2)),
                    "ratios": [],
                    "rate": rate_of(idx, rates),
                },
            )
            for name, v in (
                ("sq_f", sq_f),
                ("sq_p", sq_p),
                ("s_f", s_f),
                ("s_p", s_p),
                ("subst", np.array(subst)),
                ("rows_f", np.square(rows_f)),
                ("rows_p", np.square(rows_p)),
            ):
                acc[name] += v
            acc.setdefault("mc_f", []).extend(mc_f)
            acc.setdefault("mc_p", []).extend(mc_p)
            acc["draws"] += 1
            acc["ratios"].append(float(np.sqrt(sq_p.sum() / sq_f.sum())))
            noise_d = sq_f.sum() - s_f.sum()
            acc.setdefault("expected", []).append(
                float(np.sqrt((noise_d + s_p.sum()) / (noise_d + s_f.sum())))
            )
    print(f"policy {policy!r} against the fixed hour, {len(draws)} draw(s) in {dump_dir}")
    print("µg; 'soak-only': the same campaigns refitted without the accelerometer noise")
    summary = []
    for serial, a in per_sensor.items():
        n, m = a["draws"], a["draws"] * N_DIRECTIONS
        ratio = float(np.sqrt(a["sq_p"].sum() / a["sq_f"].sum()))
        # Expected ratio: the noise's share of the held-out sum of squares is the fixed hour's
        # less its soak-only part; a policy changes the soak-only part only.
        noise = a["sq_f"].sum() - a["s_f"].sum()
        expected = float(np.sqrt((noise + a["s_p"].sum()) / (noise + a["s_f"].sum())))
        mc_ratio, mc_half = math.nan, math.nan
        if a.get("mc_f"):
            mf, mp = np.array(a["mc_f"]), np.array(a["mc_p"])
            mc_ratio = float(np.sqrt(mp.sum() / mf.sum()))
            each = np.sqrt(mp / mf)
            mc_half = 2.0 * float(np.std(each, ddof=1)) / math.sqrt(each.size)
        a["mc"] = (mc_ratio, mc_half)
        summary.append((serial, a["rate"], ratio, expected, a["ratios"], a["expected"]))
        print(
            f"\n{serial} (rate {a['rate']:g}): held-out ×{ratio:.3f} over {n} draw(s) (each "
            f"{' '.join(f'{r:.3f}' for r in a['ratios'])}); soak-only "
            f"{1e6 * np.sqrt(a['s_f'].sum() / (m * HELDOUT_C.size)):.2f} → "
            f"{1e6 * np.sqrt(a['s_p'].sum() / (m * HELDOUT_C.size)):.2f} µg, expected "
            f"ratio ×{expected:.3f}"
        )
        print("  held-out °C         " + " ".join(f"{t:>6.0f}" for t in HELDOUT_C))
        for label, key in (
            ("fixed hour", "sq_f"),
            ("policy", "sq_p"),
            ("soak-only fixed", "s_f"),
            ("soak-only policy", "s_p"),
        ):
            print(f"  {label:<19} " + " ".join(f"{v:6.2f}" for v in 1e6 * np.sqrt(a[key] / m)))
        tot = a["sq_f"].sum() / n
        print("  step                " + " ".join(f"{s:>6d}" for s in range(len(a["subst"]))))
        print("  subst Δ % of fixed  " + " ".join(f"{100 * v / n / tot:6.2f}" for v in a["subst"]))
        for label, key in (("fixed", "rows_f"), ("policy", "rows_p")):
            r = np.sqrt(a[key] / n)
            print(f"  rows {label:<7} common " + " ".join(f"{v:6.2f}" for v in r[:, 0]))
            print(f"  rows {label:<7} varying" + " ".join(f"{v:6.2f}" for v in r[:, 1]))
    print(
        "\nper sensor over the draws: the held-out ratio pooled over them, ± 2 sd of one draw's "
        "ratio / √draws; draws needed for that ± to be 0.05; the expected ratio (mean ± sd "
        "over the draws); with --mc, the ratio of the mean held-out sum of squares over fresh "
        "noise draws on each campaign's own rows (± 2 sd / √(campaigns × mc))"
    )
    print(
        f"{'sensor':<10} {'rate':>5} {'held-out ×':>10} {'± 2σ/√n':>8} {'n for ±.05':>10} "
        f"{'expected ×':>10} {'sd':>6} {'mc ×':>7} {'±':>6}  per draw"
    )
    for serial, rate, ratio, expected, each, exp_each in summary:
        sd = float(np.std(each, ddof=1)) if len(each) > 1 else math.nan
        half = 2.0 * sd / math.sqrt(len(each))
        need = math.ceil((2.0 * sd / 0.05) ** 2) if math.isfinite(sd) else 0
        sd_exp = float(np.std(exp_each, ddof=1)) if len(exp_each) > 1 else math.nan
        mc_ratio, mc_half = per_sensor[serial]["mc"]
        print(
            f"{serial:<10} {rate:5g} {ratio:10.3f} {half:8.3f} {need:10d} {expected:10.3f} "
            f"{sd_exp:6.3f} {mc_ratio:7.3f} {mc_half:6.3f}  " + " ".join(f"{r:.3f}" for r in each)
        )
    worst = max(summary, key=lambda r: r[2])
    worst_exp = max(summary, key=lambda r: r[3])
    worst_mc = max(per_sensor.items(), key=lambda kv: kv[1]["mc"][0])
    print(
        f"worst sensor: held-out ×{worst[2]:.3f} ({worst[0]}), expected ×{worst_exp[3]:.3f} "
        f"({worst_exp[0]}), mc ×{worst_mc[1]['mc'][0]:.3f} ± {worst_mc[1]['mc'][1]:.3f} "
        f"({worst_mc[0]})"
    )


def step_row_error_ug(errors: dict[tuple, np.ndarray], step: int) -> tuple[float, float]:
    """A step's row errors (noise-free rows: the soak's alone): |mean| over its positions
    (common to the step: shifts its temperature) and the rms about it (varying), µg."""
    e = np.array([v for k, v in errors.items() if k[0] == step]) * 1e6
    mean = e.mean(axis=0)
    return float(np.linalg.norm(mean)), float(np.sqrt(np.mean(np.sum((e - mean) ** 2, axis=1))))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dump", type=Path, help="the folder of bench_throughput.py --dump")
    ap.add_argument("--policy", default=POLICIES[1])
    ap.add_argument("--sensors", default="", help="serials (default: all)")
    ap.add_argument(
        "--mc", type=int, default=0, help="fresh noise draws per campaign for the expected ratio"
    )
    args = ap.parse_args()
    analyse(args.dump, args.policy, [s for s in args.sensors.split(",") if s] or None, args.mc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
