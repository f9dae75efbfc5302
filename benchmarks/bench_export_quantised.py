"""What a firmware does with a model fitted in a rebuilt temperature: gen2 1 °C warm-ups.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.bench_export_quantised \\
        --realdata DIR [--only 1004,1009,...] [--coarse-dither]

soakcal fits a warm-up read by a coarse (1 °C) channel in the die temperature rebuilt from
the channel's crossings (:mod:`calibration.temperature_dequantise`); PX4 and ArduPilot
apply the exported offset polynomial at their own raw 1 °C reading. Per gen2 case
(:func:`benchmarks.blind.gen2.warmup.draw_case`, scored as ``bench_warmup_gen2`` scores
it: 10-s blocks alternately fit and held out, RMS of held-out 5-s means, mg x / y / z):

* ``soakcal``: ``soakcal compensate`` (the rebuilt temperature);
* ``export at raw``: the file ``soakcal export --format px4`` writes, applied by PX4's
  formula (``calc_thermal_offsets_3D``: the offset at the raw reading clamped to
  TMIN/TMAX, :mod:`calibration.export_firmware`) to every sample: what the exported file
  does in flight. For a rebuilt fit that file carries the raw-reading polynomial (the
  least-squares fit of the model's offset against the reading);
* ``model at raw``: soakcal's model, bias polynomial b(T) only, evaluated at the raw
  reading clamped to its valid range: what the export wrote before the raw-reading
  polynomial;
* ``export drop``: the same export of the model with its ``rate_fold`` record removed
  (a model with a rate term k(T)·dT/dt: the static polynomial, the rate term dropped, as
  the export wrote before :func:`calibration.firmware_polynomial.rate_fold_record`; the same
  file as ``export at raw`` for a model without a rate term);
* ``px4``, ``ardupilot``: the peers' own fits, applied at the raw reading;
* ``--as-flown``: also each file as its firmware flies it
  (:func:`benchmarks.bench_warmup_peers.evaluate_flown`: PX4's 1-s poll and 1 °C
  publication gate, ArduPilot's 1-Hz temperature filter), the peers' and the export's;
* ``stated``: the RMS the export states (``provenance.quantised_temperature.rms_mg``:
  the file's offset at each sample's reading less the model's whole offset, rate term
  included, over the fit log's capture means), against ``file − model``: the same
  difference measured here on the held-out 5-s means (the file applied at each sample's
  raw reading less ``soakcal compensate``'s offset), and ``extra``: √(at raw² −
  soakcal²), which equals it only where the two errors are unrelated. (b(raw) −
  b(die) against the generator's die temperature is no measure of it: a channel carries
  an offset and a lag from the die, which the model, fitted in the channel's own scale,
  absorbs.)
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_warmup_peers import (  # noqa: E402
    MEAN_S,
    WarmupLog,
    blocks,
    evaluate_flown,
    fit_blocks_rms_mg,
    flown_table,
    heldout_rms_mg,
    imported_log,
    method_ardupilot,
    method_px4,
    method_soakcal,
    stated_table,
    stated_vs_measured,
)
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir  # noqa: E402
from benchmarks.blind.gen2.warmup import draw_case, import_args, simulate, write_log  # noqa: E402
from calibration import sfem  # noqa: E402
from calibration.export_firmware import (  # noqa: E402
    STANDARD_GRAVITY_M_S2,
    export_ardupilot,
    export_px4,
    firmware_reading_record,
)
from calibration.model_file import load_model  # noqa: E402

# the paired bootstrap of export ÷ peer resamples windows of this length (5-s means within
# one are not independent: a 1 °C level lasts tens of seconds and its within-step error is
# shared by its means), with this many draws
WINDOW_S, DRAWS = 60.0, 2000

# the default draws of seeds 1000-1059 and 2000-2029 with a 1 °C channel (kind quant1C)
QUANT1C = "1004,1009,1011,1016,1023,1039,2001,2012,2019,2028"


def run_case(seed: int, coarse_dither: bool, pools: object, work: Path,
             window_s: float = WINDOW_S, as_flown: bool = False) -> dict[str, object]:
    case = draw_case(seed, coarse_dither)
    data = simulate(case, pools)  # type: ignore[arg-type]
    csv_path, _ = write_log(case, data, work)
    log, said = imported_log(csv_path, "csv", import_args(case), work)
    out: dict[str, object] = {"case": case.name + ("d" if coarse_dither else ""),
                              "kinds": list(case.kinds)}
    if log is None:
        return out | {"unusable": said}
    sc, note = method_soakcal(log, work)
    if sc is None:
        return out | {"soakcal": None, "note": note}
    model = load_model(work / "model.json")
    lo, hi = model.valid_c or (float(log.temp_c.min()), float(log.temp_c.max()))

    def bias_g(t: np.ndarray) -> np.ndarray:
        return model.params_vector_at(np.clip(t, lo, hi), extrapolate=True)[:, sfem.BIAS]

    at_raw = log.acc_g - bias_g(log.temp_c)
    exported = log.acc_g - px4_offset_g(export_px4(model).text, log.temp_c)
    # the figures the export states (a folded rate term's file: rate_fold's)
    record = firmware_reading_record(model) or {}
    model.provenance.pop("rate_fold", None)
    dropped = log.acc_g - px4_offset_g(export_px4(model).text, log.temp_c)
    px4, ardupilot = method_px4(log), method_ardupilot(log)[0]
    ok = np.all(np.isfinite(sc), axis=1)
    own, raw = heldout_rms_mg(log, sc), heldout_rms_mg(log, exported)
    if as_flown:
        out |= evaluate_flown(log, work / "model.json", window_s)
    res = out | {
        "soakcal": own.tolist() if ok.all() else None,
        "export_at_raw": raw.tolist(),
        "model_at_raw": heldout_rms_mg(log, at_raw).tolist(),
        "rate_term": bool(model.temperature_rate),
        "px4": heldout_rms_mg(log, px4).tolist(),
        "ardupilot": heldout_rms_mg(log, ardupilot).tolist(),
        "export_over_peer_95": ratio_interval(log.t_s, exported, (px4, ardupilot), window_s),
        "export_drop": heldout_rms_mg(log, dropped).tolist(),
        "export_drop_over_peer_95": ratio_interval(log.t_s, dropped, (px4, ardupilot),
                                                   window_s),
        "export_over_drop_95": ratio_interval(log.t_s, exported, (dropped,), window_s),
        "stated_rms_mg": record.get("rms_mg"), "ratio_to_fit": record.get("ratio_to_fit"),
        "extra_rms_mg": np.sqrt(np.maximum(raw**2 - own**2, 0.0)).tolist(),
        # what the stated figure claims, measured directly: the file's offset at each
        # sample's raw reading against the model's whole offset (compensate's), held out
        "file_vs_model_mg": heldout_rms_mg(log, exported - sc).tolist(),
    }
    # the header's stated RMS (a fine channel's: the FOLDED line's) against the measured,
    # in-sample and held out; and the file against the generator's truth, held out
    res |= stated_vs_measured(log, work / "model.json", sc)
    if data.t_s.size == log.t_s.size:
        truth = WarmupLog(log.name, log.t_s, data.true_g - (log.acc_g - exported),
                          log.temp_c)
        res["file_vs_truth_heldout_mg"] = heldout_rms_mg(truth, truth.acc_g).tolist()
    res |= ardupilot_stated(log, work / "model.json", sc)
    return res


def ardupilot_stated(log: WarmupLog, model_path: Path, soakcal_g: np.ndarray
                     ) -> dict[str, object]:
    """The ArduPilot file's stated RMS (file − model) at the reading its InvenSense drivers'
    filter hands it (the record of a dithered channel's filtered fit; else per sample)
    against the measured: the ``--format ardupilot`` file at
    :func:`calibration.firmware_flight.ardupilot_reading_in_use` less ``compensate``'s
    offset, held out and on the fit blocks."""
    from calibration.firmware_flight import ardupilot_reading_in_use

    model = load_model(model_path)
    record = firmware_reading_record(model, filtered=True) or {}
    fold = model.provenance.get("rate_fold") or {}
    if record.get("fitted_filtered"):
        stated = record.get("smoothed_rms_mg")
    else:
        stated = record.get("rms_mg") or fold.get("rms_mg")
    ok = np.all(np.isfinite(soakcal_g), axis=1)
    at = ardupilot_reading_in_use(log.t_s, log.temp_c)
    flown = log.acc_g - ardupilot_offset_g(export_ardupilot(model).text, at)
    sub = WarmupLog(log.name, log.t_s[ok], log.acc_g[ok], log.temp_c[ok])
    diff = flown[ok] - soakcal_g[ok]
    return {"ardupilot_stated_rms_mg": stated,
            # the per-sample fold's figure, which the ArduPilot FOLDED line stated before
            "per_sample_fold_rms_mg": fold.get("rms_mg"),
            "ardupilot_file_vs_model_fit_mg": fit_blocks_rms_mg(sub, diff).tolist(),
            "ardupilot_file_vs_model_heldout_mg": heldout_rms_mg(sub, diff).tolist()}


def ratio_interval(t_s: np.ndarray, ours_g: np.ndarray, peers_g: tuple[np.ndarray, ...],
                   window_s: float = WINDOW_S) -> list[list[float]]:
    """Per axis, a 95 % interval of held-out RMS(ours) ÷ RMS(better peer) (as
    :func:`heldout_rms_mg`: held-out 5-s means less the fit samples' mean): a paired
    bootstrap over ``window_s`` windows of the held-out means, the better peer chosen
    on each draw."""
    _, fit = blocks(t_s)
    half = np.floor((t_s - t_s[0]) / MEAN_S).astype(int)
    rate = (t_s.size - 1) / (t_s[-1] - t_s[0])
    hs = [h for h in np.unique(half[~fit]) if np.sum(half == h) > 0.8 * MEAN_S * rate]

    def errors(c: np.ndarray) -> np.ndarray:
        ref = c[fit].mean(axis=0)
        return np.array([c[half == h].mean(axis=0) - ref for h in hs])  # (m, 3)

    sq = np.stack([errors(c) ** 2 for c in (ours_g, *peers_g)])  # (methods, m, 3)
    window = (np.asarray(hs) * MEAN_S // window_s).astype(int)
    groups = [np.flatnonzero(window == w) for w in np.unique(window)]
    rng = np.random.default_rng(0)
    ratios = []
    for _ in range(DRAWS):
        pick = np.concatenate([groups[i] for i in rng.integers(0, len(groups), len(groups))])
        ms = sq[:, pick].mean(axis=1)  # (methods, 3)
        ratios.append(np.sqrt(ms[0] / np.min(ms[1:], axis=0)))
    lo, hi = np.percentile(np.asarray(ratios), [2.5, 97.5], axis=0)
    return [[float(a), float(b)] for a, b in zip(lo, hi, strict=True)]


def px4_offset_g(params_text: str, temp_c: np.ndarray) -> np.ndarray:
    """(N, 3) g: PX4's offset X0 + X1 d + X2 d² + X3 d³, d = clamp(T, TMIN, TMAX) − TREF
    (``TemperatureCompensation::calc_thermal_offsets_3D``), from a ``TC_A0_*`` file."""
    p = {}
    for line in params_text.splitlines():
        if line and not line.startswith("#"):
            _veh, _comp, name, value, _type = line.split("\t")
            p[name] = float(value)
    d = np.clip(temp_c, p["TC_A0_TMIN"], p["TC_A0_TMAX"]) - p["TC_A0_TREF"]
    return np.column_stack([sum(p[f"TC_A0_X{j}_{i}"] * d**j for j in range(4))
                            for i in range(3)]) / STANDARD_GRAVITY_M_S2


def ardupilot_offset_g(params_text: str, temp_c: np.ndarray) -> np.ndarray:
    """(N, 3) g: ArduPilot's offset P(clamp(T) − 35), P(d) = (ACC1 d + ACC2 d² + ACC3 d³)
    × 1e−6 m/s² (``AP_InertialSensor::TCal::correct_sensor``), from an ``INS_TCAL1_*``
    file; the constant P(clamp(T_cal) − 35) is left out (a constant: INS_ACCOFFS's)."""
    p = {}
    for line in params_text.splitlines():
        if line and not line.startswith("#"):
            name, value = line.split(",")
            p[name] = float(value)
    d = np.clip(temp_c, p["INS_TCAL1_TMIN"], p["INS_TCAL1_TMAX"]) - 35.0
    return np.column_stack([sum(p[f"INS_TCAL1_ACC{j}_{axis}"] * d**j for j in (1, 2, 3))
                            for axis in "XYZ"]) * 1e-6 / STANDARD_GRAVITY_M_S2


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--realdata", help="the shared real recordings (noise pools)")
    ap.add_argument("--only", default=QUANT1C, help="comma-separated case seeds")
    ap.add_argument("--coarse-dither", action="store_true")
    ap.add_argument("--as-flown", action="store_true",
                    help="also each file as its firmware flies it (PX4's 1-s poll and 1 degC "
                         "gate, ArduPilot's 1-Hz temperature filter)")
    ap.add_argument("--window-s", type=float, default=WINDOW_S,
                    help="the bootstrap's window of held-out means (s)")
    args = ap.parse_args(argv)
    pools = load_pools(realdata_dir(args.realdata))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in (int(x) for x in args.only.split(",")):
            r = run_case(s, args.coarse_dither, pools, Path(tmp), args.window_s,
                         args.as_flown)
            rows.append(r)
            print(json.dumps(r), flush=True)

    def f(v: object) -> str:
        return "—" if v is None else " / ".join(f"{x:.3f}" for x in v)  # type: ignore[union-attr]

    print("| case | soakcal (rebuilt) | export at raw | model b(T) at raw | PX4 fit at raw | "
          "ArduPilot at raw | export ÷ better peer (95 %) | stated RMS | file − model | "
          "extra at raw | ratio to fit | rate term | export drop | drop ÷ better peer (95 %) "
          "| export ÷ drop (95 %) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = r.get("ratio_to_fit")
        vs = drop_vs = fold_vs = "—"

        def with_ci(values: np.ndarray, ci: object) -> str:
            return " / ".join(f"{v:.3f} ({a:.2f}–{b:.2f})" for v, (a, b) in zip(
                values, ci, strict=True))  # type: ignore[call-overload]

        if r.get("export_at_raw") is not None:
            peer = np.minimum(r["px4"], r["ardupilot"])  # type: ignore[arg-type]
            vs = with_ci(np.asarray(r["export_at_raw"]) / peer, r["export_over_peer_95"])
            drop_vs = with_ci(np.asarray(r["export_drop"]) / peer,
                              r["export_drop_over_peer_95"])
            fold_vs = with_ci(np.asarray(r["export_at_raw"]) / np.asarray(r["export_drop"]),
                              r["export_over_drop_95"])
        print(f"| {r['case']} | {f(r.get('soakcal'))} | {f(r.get('export_at_raw'))} | "
              f"{f(r.get('model_at_raw'))} | {f(r.get('px4'))} | {f(r.get('ardupilot'))} | "
              f"{vs} | {f(r.get('stated_rms_mg'))} | {f(r.get('file_vs_model_mg'))} | "
              f"{f(r.get('extra_rms_mg'))} | "
              f"{'—' if ratio is None else f'{ratio:.1f}'} | "
              f"{'yes' if r.get('rate_term') else 'no'} | {f(r.get('export_drop'))} | "
              f"{drop_vs} | {fold_vs} |")
    print("\nThe stated RMS (file − model) against the measured; the file against the "
          "generator's truth, held out; the ArduPilot file through its 1-Hz filter:\n")
    print(stated_table([r | {"log": r["case"]} for r in rows if "stated_what" in r]))
    print("\n| case | file − truth held out | ArduPilot stated | ArduPilot fit blocks | "
          "ArduPilot held out |\n|---|---|---|---|---|")
    for r in rows:
        if "stated_what" in r:
            print(f"| {r['case']} | {f(r.get('file_vs_truth_heldout_mg'))} | "
                  f"{f(r.get('ardupilot_stated_rms_mg'))} | "
                  f"{f(r.get('ardupilot_file_vs_model_fit_mg'))} | "
                  f"{f(r.get('ardupilot_file_vs_model_heldout_mg'))} |")
    if args.as_flown:
        print("\nEach file as its firmware flies it (--as-flown; export per sample = export at "
              "raw):\n")
        print(flown_table([r | {"log": r["case"], "export": r.get("export_at_raw")}
                           for r in rows if "px4_flown" in r]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
