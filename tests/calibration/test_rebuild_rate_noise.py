"""dT/dt's noise on a temperature rebuilt from a coarse channel: the rebuild's own error."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.rebuild_rate_noise import rebuild_rate_noise
from calibration.temperature_conditioning import (
    rate_noise_c_per_min,
    temperature_noise_c,
    temperature_rate_c_per_min,
)
from calibration.temperature_dequantise import dequantise
from tests.calibration.dequantise_cases import RATE_HZ
from tests.calibration.dequantise_cases import captures as _captures
from tests.calibration.dequantise_cases import heat_cool as _heat_cool
from tests.calibration.dequantise_cases import overshoot as _overshoot


@pytest.mark.parametrize("profile, noise_c", [(_overshoot, 0.0), (_heat_cool, 0.01),
                                              (_overshoot, 0.35)])
def test_the_rebuilds_rate_error_is_measured_not_taken_for_white_noise(profile, noise_c) -> None:
    t, read, truth = _captures(profile, noise_c, 5.0)
    n = np.full(t.size, 5.0 * RATE_HZ)
    dq = dequantise(t, read, n)
    assert dq.rebuilt
    noise = rebuild_rate_noise(t, dq, n)
    trace = dq.temperature_c
    for window in (20.0, 40.0, 120.0):
        actual = float(np.sqrt(np.mean((temperature_rate_c_per_min(t, trace, window)
                                        - temperature_rate_c_per_min(t, truth, window)) ** 2)))
        white = rate_noise_c_per_min(t, window, temperature_noise_c(t, trace))
        # the smooth rebuilt trace looks nearly noiseless to the white-noise model, while
        # its dT/dt is wrong by what the redone rebuild measures (within a factor of 3)
        assert white < 0.5 * actual
        assert actual / 3.0 < noise(window) < 3.0 * actual
    assert noise(120.0) < noise(20.0)


def test_a_channel_used_as_read_adds_nothing() -> None:
    t, _, truth = _captures(_heat_cool, 0.0, 5.0)
    dq = dequantise(t, truth)
    assert not dq.rebuilt and rebuild_rate_noise(t, dq)(20.0) == 0.0
