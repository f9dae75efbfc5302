"""Joint vs per-step thermal fit (docs/calibration.md): which predicts unseen data better?

    .venv/bin/python benchmarks/bench_thermal_method.py [--sensors 30]

Same protocol as ``bench_heldout_accuracy.py`` (calibrate on a simulated
−40…60 °C campaign, compensate a separate run at −35/−5/25/55 °C in random
orientations, RMS vector error over the noise-limited oracle), run for both
methods on the *same* sensors and noise (a paired comparison), in scenarios
that stress what the methods do differently:

* ``nominal``       60 min soak, 200 samples/position, temperature noise 0.1 °C/sample
* ``short_soak``    15 min soak: the die still creeps during a step's positions, so
                    the per-reading temperatures the joint fit uses matter (the die
                    never reaches the end setpoints: compensated with extrapolate)
* ``noisy_temp``    temperature channel 2 °C rms per raw sample (0.14 °C per reading)
* ``noisy_temp_smoothed`` the same, the verification run's temperature smoothed over
                    600 s (``smooth_over_time``) before compensation
* ``few_samples``   20 samples/position in the campaign (verification keeps 200):
                    the parameters are less certain than the readings they compensate

Prints, per scenario, the pooled ratio of each method and the paired mean
difference (joint − per_step) of the per-sensor ratios with its standard error.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_heldout_accuracy import heldout_case  # noqa: E402

SCENARIOS: dict[str, dict[str, float | bool]] = {
    "nominal": {},
    "short_soak": {"soak_min": 15.0, "extrapolate": True},
    "noisy_temp": {"temp_noise_c": 2.0},
    "noisy_temp_smoothed": {"temp_noise_c": 2.0, "smooth_temperature_s": 600.0},
    "few_samples": {"samples_per_position": 20},
}


def compare(sensors: int, scenario: dict[str, float | bool]) -> dict[str, float]:
    res = {m: [heldout_case(s, m, **scenario) for s in range(sensors)]  # type: ignore[arg-type]
           for m in ("per_step", "joint")}
    out: dict[str, float] = {}
    for m, rows in res.items():
        out[m] = float(np.sqrt(sum(r["sse_model"] for r in rows) /
                               sum(r["sse_oracle"] for r in rows)))
    d = np.array([j["ratio"] - p["ratio"] for j, p in zip(res["joint"], res["per_step"],
                                                          strict=True)])
    out["diff"] = float(d.mean())
    out["diff_se"] = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else float("nan")
    out["joint_better"] = int(np.sum(d < 0))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sensors", type=int, default=30)
    ap.add_argument("--scenario", choices=tuple(SCENARIOS) + ("all",), default="all")
    a = ap.parse_args(argv)
    names = tuple(SCENARIOS) if a.scenario == "all" else (a.scenario,)
    print(f"held-out RMS vector error / oracle, {a.sensors} sensors per scenario (paired)")
    print(f"{'scenario':>20} {'per_step':>9} {'joint':>9} {'joint-per_step':>16} "
          f"{'joint better':>13}  time")
    for name in names:
        t0 = time.perf_counter()
        r = compare(a.sensors, SCENARIOS[name])
        print(f"{name:>20} {r['per_step']:9.4f} {r['joint']:9.4f} "
              f"{r['diff']:+8.4f} ± {r['diff_se']:.4f} {r['joint_better']:>6}/{a.sensors:<6}"
              f" {time.perf_counter() - t0:5.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
