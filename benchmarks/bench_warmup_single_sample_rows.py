"""Warm-up logs of single-sample rows: how often the warm-up solver establishes a bias change
(a degree above 0), with the held-out blocks' means test (:func:`calibration.warmup.
_block_means_beat`) and without it (the share rule alone, :data:`calibration.warmup.MIN_GAIN`).

Usage::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.bench_warmup_single_sample_rows \\
        [--rows 18000] [--seeds 200] [--changes-mg 0,4,6,8,10,20] [--out FILE]

Each case: ``--rows`` rows of one sample each (white noise 20 mg per axis, z up), the
temperature 20 → 30 °C linear in time, and a linear bias change of z of the given size
over the span. The decision is the solver's own first stage (:func:`calibration.warmup.
_choose_degree` on :func:`calibration.warmup._heldout_errors_g` over the solver's
temperature-block folds, degrees 0 … 3), as ``soakcal calibrate`` makes it before any rate
term; the full ``calibrate`` on such a log takes seconds per case and makes the same
first-stage decision. At 0 mg the rate is the false establishment rate; above, the power.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.blind.score import clopper_pearson
from calibration import warmup

NOISE_G = 20e-3


def first_stage_errors(rows: int, change_g: float, seed: int
                       ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """One synthetic single-sample log through the solver's held-out machinery: the held-out
    errors (n, 3) g at degrees 0 … 3, the held-out rows' indices, and every row's
    temperature block."""
    rng = np.random.default_rng(seed)
    temp_c = np.linspace(20.0, 30.0, rows)
    raw = rng.normal(0.0, NOISE_G, (rows, 3))
    raw[:, 2] += 1.0 + change_g * (temp_c - 25.0) / 10.0
    x = (temp_c - 25.0) / 5.0
    labels = np.zeros(rows, int)
    folds = warmup._folds(temp_c)
    errors = [warmup._heldout_errors_g(x, labels, raw, folds, d)
              for d in range(warmup.MAX_DEGREE + 1)]
    return [e for e, _ in errors], errors[0][1], warmup._block_index(temp_c)


def degree_chosen(rows: int, change_g: float, seed: int, strong: bool) -> int:
    """The solver's first-stage degree on one synthetic single-sample log."""
    errors, held, block = first_stage_errors(rows, change_g, seed)
    saved = warmup._block_means_beat
    if not strong:
        warmup._block_means_beat = lambda *_: False  # the share rule alone
    try:
        return warmup._choose_degree(errors, held, block)
    finally:
        warmup._block_means_beat = saved


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=18000)
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--changes-mg", default="0,4,6,8,10,20")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    args = ap.parse_args(argv)
    results = []
    print(f"{args.rows} single-sample rows, 20 mg noise, 20 → 30 °C; a change established "
          f"(degree > 0) in {args.seeds} seeds, 95 % intervals")
    print("| z change over the span | share rule alone | with the block means' test |")
    print("|---|---|---|")
    for change_mg in (float(v) for v in args.changes_mg.split(",")):
        counts = {}
        for strong in (False, True):
            counts[strong] = sum(degree_chosen(args.rows, change_mg * 1e-3, seed, strong) > 0
                                 for seed in range(args.seeds))
        cells = []
        for strong in (False, True):
            k = counts[strong]
            lo, hi = clopper_pearson(k, args.seeds)
            cells.append(f"{k}/{args.seeds} ({100 * lo:.1f}–{100 * hi:.1f} %)")
        print(f"| {change_mg:g} mg | {cells[0]} | {cells[1]} |")
        results.append({"change_mg": change_mg, "share_rule": counts[False],
                        "with_block_means": counts[True], "seeds": args.seeds})
        sys.stdout.flush()
    if args.out is not None:
        args.out.write_text(json.dumps({"rows": args.rows, "results": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
