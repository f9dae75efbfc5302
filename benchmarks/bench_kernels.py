"""Time of the shared physics kernels (Eq. 1 and its Jacobian, the twin's sensor, a campaign).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_kernels.py

Run from a checkout's root (its packages come first on ``sys.path``), so that two trees
can be timed with the same script. Best of 5 repeats per row, in ms.
"""

from __future__ import annotations

import sys
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

from calibration import fit, sfem  # noqa: E402
from calibration.schedules import table1  # noqa: E402
from simulators.campaign_sim import simulate_campaign  # noqa: E402
from simulators.truth import SensorTruth  # noqa: E402


def main() -> None:
    rng = np.random.default_rng(0)
    p = sfem.identity_vector() + rng.normal(0, 0.01, 12)
    raw24 = rng.normal(0, 1, (24, 3))
    rows = np.tile(sfem.identity_vector(), (5000, 1)) + rng.normal(0, 0.01, (5000, 12))
    raw5k = rng.normal(0, 1, (5000, 3))
    truth = SensorTruth.adxl355_typical(seed=7)
    pos24 = truth.ideal_raw_g(table1(), 10.0) + rng.normal(0, 20e-6, (24, 3))
    temp5k = rng.uniform(-40, 60, 5000)
    cases = [
        ("forward_jacobian, one p, 24 rows", lambda: sfem.forward_jacobian(p, raw24), 2000),
        # Trees before branch dup10 also had this as sfem_batch.forward_jacobian (before
        # merge10, its own copy): time those with their own script.
        ("forward_jacobian, 5000 rows of p", lambda: sfem.forward_jacobian(rows, raw5k), 30),
        ("fit_reference, 24 positions", lambda: fit.fit_reference(pos24, table1()), 30),
        ("SensorTruth.ideal_raw_g, 5000 rows", lambda: truth.ideal_raw_g(raw5k, temp5k), 3),
        ("simulate_campaign, 11 steps x 24", lambda: simulate_campaign(truth, seed=1), 1),
    ]
    for name, fn, number in cases:
        best = min(timeit.repeat(fn, number=number, repeat=5)) / number
        print(f"{name:40s} {best * 1e3:9.3f} ms")


if __name__ == "__main__":
    main()
