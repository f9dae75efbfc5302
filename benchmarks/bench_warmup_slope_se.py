"""The warm-up fit's stated bias-slope standard error against its spread over noise draws,
by the degree held-out error chose (issue 20).

A linear truth (z bias 2 mg/°C over 20 → 30 °C, 60 five-second captures, 2 mg of white
noise per capture mean), fitted by ``calibration.fitting.fit`` as a one-orientation
warm-up, many times with new noise. For each draw: the chosen degree, the z slope at two
temperatures and two standard errors of it (``gate.bias_slope_g_per_c``): the one stated
(the report's and the model file's, with the choice of the degree in it) and the chosen
fit's own (what the gate judges the applied curve by). A table for each gives, per chosen
degree, the slopes' spread over the error (1 for an honest error) and how often the truth
lies within ±2 errors (95 % for an honest Gaussian error).

Why: held-out error chooses the degree (``warmup._choose_model``: the simplest model within
``MIN_GAIN`` of the lowest held-out RMS). Where noise makes a curvature look real a higher
degree is chosen, and its slope is then the noisier one; the stated error is the chosen
model's, given that it was chosen, so across draws it can understate the spread; the
stated error adds the choice's term (``warmup._selection_cov``).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.bench_warmup_slope_se \
        --draws 400 --seed 11
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from calibration import gate
from calibration.fitting import fit
from calibration.recording import Recording

SLOPE_G_PER_C = 2e-3
NOISE_G = 2e-3
AT_C = (21.0, 25.0)


def draw_slopes(draws: int, seed: int) -> np.ndarray:
    """(draws, 1 + 3·len(AT_C)): chosen degree, then (slope, stated se, the fit's own se)
    at each AT_C, g/°C."""
    rng = np.random.default_rng(seed)
    t_s = np.arange(60, dtype=float) * 5.0
    temp_c = 20.0 + 10.0 * t_s / t_s[-1]
    rows = []
    for _ in range(draws):
        z = 1.0 + SLOPE_G_PER_C * (temp_c - 20.0) + rng.normal(0.0, NOISE_G, t_s.size)
        rec = Recording.from_columns({
            "t_s": t_s, "sensor_c": temp_c, "ax": np.zeros(t_s.size), "ay": np.zeros(t_s.size),
            "az": z, "sd_x": np.full(t_s.size, 1e-3), "sd_y": np.full(t_s.size, 1e-3),
            "sd_z": np.full(t_s.size, 1e-3), "n": np.full(t_s.size, 50.0)})
        model = fit(rec).model
        slope, stated = gate.bias_slope_g_per_c(model, np.array(AT_C), with_choice=True)
        _, own = gate.bias_slope_g_per_c(model, np.array(AT_C))
        rows.append([model.degree, *np.ravel(np.column_stack([slope[2], stated[2], own[2]]))])
    return np.array(rows)


def table(rows: np.ndarray, which: str = "stated") -> str:
    """Per chosen degree: spread / error and coverage, for the stated error or the fit's own
    (``which``: "stated" | "own")."""
    col = 1 if which == "stated" else 2
    rows = np.column_stack([rows[:, 0], *[rows[:, [1 + 3 * j, 1 + 3 * j + col]]
                                          for j in range(len(AT_C))]])
    head = "| chosen degree | draws | " + " | ".join(
        f"spread / {which} at {t:g} °C | truth within ±2 {which} at {t:g} °C" for t in AT_C) + " |"
    lines = [head, "|" + "---|" * (2 + 2 * len(AT_C))]
    groups = [(f"{int(d)}", rows[:, 0] == d) for d in np.unique(rows[:, 0])]
    groups.append(("all", np.ones(len(rows), bool)))
    for name, sel in groups:
        r = rows[sel]
        cells = [name, str(len(r))]
        for j in range(len(AT_C)):
            s, se = r[:, 1 + 2 * j], r[:, 2 + 2 * j]
            ratio = float(np.std(s, ddof=1) / np.mean(se)) if len(r) > 1 else float("nan")
            cover = float(np.mean(np.abs(s - SLOPE_G_PER_C) <= 2.0 * se))
            cells += [f"{ratio:.2f}", f"{100 * cover:.1f} %"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=400)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.2f}; {args.draws} draws, seed {args.seed}")
    rows = draw_slopes(args.draws, args.seed)
    print("the stated error (report, model file: with the choice of the degree)")
    print(table(rows, "stated"))
    print("\nthe chosen fit's own error (what the gate judges the applied curve by)")
    print(table(rows, "own"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
