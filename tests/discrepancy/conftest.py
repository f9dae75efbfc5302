"""Single-threaded BLAS for these small matrices: threads only add overhead (10× under load);
and a recording two test files share."""

import os

import numpy as np
import pytest

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


@pytest.fixture
def nonlinear_recording():
    """A one-way staircase of a sensor with a z bend (K2 = 80 µg/g²), the positions in a
    seeded order per plateau: named ``scale_nonlinearity`` when nothing is forced. (In one
    order on every plateau a settling at each slot of it fits the bend as well: not named,
    slot_settling.py.)"""
    from simulators import effects as E  # noqa: N812 (as the discrepancy tests)
    from simulators.campaign_sim import simulate_campaign
    from simulators.truth import SensorTruth

    truth = SensorTruth.adxl355_typical(
        seed=1, effects=[E.ScaleNonlinearity(k2_per_g=np.array([0.0, 0.0, 80e-6]))])
    return simulate_campaign(truth, setpoints_c=[float(t) for t in range(-40, 61, 10)],
                             seed=11, position_order="random", position_order_seed=3)
