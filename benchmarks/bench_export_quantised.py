"""What a firmware does with a model fitted in a rebuilt temperature: gen2 1 °C warm-ups.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.bench_export_quantised \\
        --realdata DIR [--only 1004,1009,...] [--coarse-dither]

soakcal fits a warm-up read by a coarse (1 °C) channel in the die temperature rebuilt from
the channel's crossings (:mod:`calibration.temperature_dequantise`); PX4 and ArduPilot
apply the exported offset polynomial at their own raw 1 °C reading. Per gen2 case
(:func:`benchmarks.blind.gen2.warmup.draw_case`, scored as ``bench_warmup_gen2`` scores
it: 10-s blocks alternately fit and held out, RMS of held-out 5-s means, mg x / y / z):

* ``soakcal``: ``soakcal compensate`` (the rebuilt temperature);
* ``soakcal at raw``: soakcal's model, bias polynomial only, evaluated at the raw reading
  clamped to its valid range, as both firmwares evaluate their ``TC_A*``/``INS_TCAL*``
  (:mod:`calibration.export_firmware`): what the exported file does in flight;
* ``px4``, ``ardupilot``: the peers' own fits, applied at the raw reading;
* ``stated``: the RMS the export states (``provenance.quantised_temperature.rms_mg``:
  b(raw) − b(rebuilt) over the fit log's capture means), against ``extra``: what the
  raw reading adds to soakcal's own held-out error, √(at raw² − soakcal²). (b(raw) −
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
    heldout_rms_mg,
    imported_log,
    method_ardupilot,
    method_px4,
    method_soakcal,
)
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir  # noqa: E402
from benchmarks.blind.gen2.warmup import draw_case, import_args, simulate, write_log  # noqa: E402
from calibration import sfem  # noqa: E402
from calibration.model_file import load_model  # noqa: E402

# the default draws of seeds 1000-1059 and 2000-2029 with a 1 °C channel (kind quant1C)
QUANT1C = "1004,1009,1011,1016,1023,1039,2001,2012,2019,2028"


def run_case(seed: int, coarse_dither: bool, pools: object, work: Path) -> dict[str, object]:
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
    ok = np.all(np.isfinite(sc), axis=1)
    record = model.provenance.get("quantised_temperature") or {}
    own, raw = heldout_rms_mg(log, sc), heldout_rms_mg(log, at_raw)
    return out | {
        "soakcal": own.tolist() if ok.all() else None,
        "soakcal_at_raw": raw.tolist(),
        "px4": heldout_rms_mg(log, method_px4(log)).tolist(),
        "ardupilot": heldout_rms_mg(log, method_ardupilot(log)[0]).tolist(),
        "stated_rms_mg": record.get("rms_mg"), "ratio_to_fit": record.get("ratio_to_fit"),
        "extra_rms_mg": np.sqrt(np.maximum(raw**2 - own**2, 0.0)).tolist(),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--realdata", help="the shared real recordings (noise pools)")
    ap.add_argument("--only", default=QUANT1C, help="comma-separated case seeds")
    ap.add_argument("--coarse-dither", action="store_true")
    args = ap.parse_args(argv)
    pools = load_pools(realdata_dir(args.realdata))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in (int(x) for x in args.only.split(",")):
            r = run_case(s, args.coarse_dither, pools, Path(tmp))
            rows.append(r)
            print(json.dumps(r), flush=True)

    def f(v: object) -> str:
        return "—" if v is None else " / ".join(f"{x:.3f}" for x in v)  # type: ignore[union-attr]

    print("| case | soakcal (rebuilt) | soakcal at the raw reading | PX4 fit at raw | "
          "ArduPilot at raw | stated RMS | extra at raw | ratio to fit |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = r.get("ratio_to_fit")
        print(f"| {r['case']} | {f(r.get('soakcal'))} | {f(r.get('soakcal_at_raw'))} | "
              f"{f(r.get('px4'))} | {f(r.get('ardupilot'))} | {f(r.get('stated_rms_mg'))} | "
              f"{f(r.get('extra_rms_mg'))} | "
              f"{'—' if ratio is None else f'{ratio:.1f}'} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
