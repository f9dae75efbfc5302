"""Pure parts of the several-sensor engine: out-of-range readings, the slowest die decides."""

from __future__ import annotations

import math

import pytest

from drivers.protocols import Acquisition
from service.engine.multi import reading_problem, slowest_decision
from service.engine.stability import Decision


def _acq(mean_g: tuple[float, float, float], sensor_c: float = 25.0) -> Acquisition:
    return Acquisition(mean_g, (1e-4,) * 3, 200, sensor_c, 0.01, False, 3.2)


def test_reading_problem() -> None:
    assert reading_problem(_acq((0.01, -0.02, 0.99)), 2.0) is None
    assert "limit" in (reading_problem(_acq((0.0, 0.0, 1.99)), 2.0) or "")
    assert "|a| = 0.010 g" in (reading_problem(_acq((0.0, 0.0, 0.01)), 2.0) or "")
    assert "non-finite" in (reading_problem(_acq((math.nan, 0.0, 1.0)), 2.0) or "")
    assert "non-finite" in (reading_problem(_acq((0.0, 0.0, 1.0), math.inf), 2.0) or "")


def test_the_slowest_die_decides() -> None:
    fast = Decision(True, "predicted", tau_s=300.0)
    slow = Decision(True, "predicted", tau_s=900.0)
    waiting = Decision(False, "waiting", tau_s=1200.0)
    assert slowest_decision([fast, slow]) is slow
    assert slowest_decision([fast, waiting, slow]) is waiting
    capped = Decision(True, "max soak", tau_s=100.0, max_soak_reached=True)
    assert slowest_decision([slow, capped]) is capped
    with pytest.raises(ValueError):
        slowest_decision([])
