"""``python -m benchmarks.blind.gen3.sanity --seed S --n N --out OUT`` (issue 22): the
generator checked by the base model itself. ``soakcal calibrate`` on each case must leave a
residual RMSE near the error drawn into the means (noise, vibration, quantisation,
re-seating) along the reference, which is what its Eq. 9 RMSE (|a| − g) measures; a null the
base model does not fit is a generator bug, not a false alarm."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.blind.gen3.case import (
    draw_case,
    drawn_along_ug,
    drawn_error_ug,
    simulate,
)
from benchmarks.blind.gen3.run import case_seed
from benchmarks.blind.gen3.writer import write_csv


def calibrate_rmse_ug(csv: Path, model: Path) -> tuple[float, float]:
    """``soakcal calibrate CSV -o MODEL --json``: its Eq. 9 RMSE (|a| − g) and the RMS over
    steps of the vector residual after the polynomial (per axis), in µg."""
    from service.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["calibrate", str(csv), "-o", str(model), "--json"])
    if code != 0:
        raise RuntimeError(f"calibrate refused {csv}")
    doc = json.loads(buf.getvalue())
    vec = [s["rmse_vector_polynomial_mg"] for s in doc["steps"]]
    return float(doc["rmse_ug"]), float(np.sqrt(np.mean(np.square(vec))) * 1e3)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print("| case | schedule | features | drawn along ref µg | calibrate \\|a\\|−g RMSE µg "
          "| ratio | drawn per axis µg | calibrate vector RMSE µg | ratio |\n"
          "|---|---|---|---|---|---|---|---|---|")
    for i in range(args.n):
        case = draw_case(case_seed(args.seed, i))
        rows = simulate(case)
        csv = out / f"sanity-{i}.csv"
        write_csv(rows, csv)
        rmse, vector = calibrate_rmse_ug(csv, out / f"sanity-{i}.json")
        along, per_axis = drawn_along_ug(rows), drawn_error_ug(rows)
        f = case.features()
        tags = [k for k, v in (("t", f["heavy_nu"]), ("vib", f["vibration_rms_mg"]),
                               ("q", f["raw_lsb_ug"]), ("hand", f["fixture"] == "hand")) if v]
        print(f"| {i} | {f['schedule']}×{f['visits']} | {','.join(tags) or 'white'} | "
              f"{along:.1f} | {rmse:.1f} | {rmse / along:.2f} | {per_axis:.1f} | "
              f"{vector:.1f} | {vector / per_axis:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
