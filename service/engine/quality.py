"""Per-position quality checks on one acquisition: pure functions.

A failed check makes the engine measure the position once more; if the
second capture fails too it is stored anyway with ``flags`` (a comma list of
the names below) and ``attempts = 2``, so the fit can weigh or drop it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from calibration.campaign_spec import (
    DEFAULT_EXPECTED_SD_G,
    DEFAULT_MAX_SPAN_C,
    DEFAULT_TEMP_NOISE_C,
)
from drivers.protocols import Acquisition

CHECKS = ("sample_count", "noise_sd", "temperature_span", "saturated")


@dataclass(frozen=True)
class QualityLimits:
    expected_sd_g: float = DEFAULT_EXPECTED_SD_G  # rms noise of one raw sample
    sd_factor: float = 5.0  # sd above sd_factor × expected_sd_g: vibration, a bump, a bad cable
    max_span_c: float = DEFAULT_MAX_SPAN_C  # die moved during the capture: not static
    # rms noise of one raw temperature-channel sample. The driver reports max − min of the
    # raw channel, which for n noisy samples is ≈ 2σ·√(2 ln n) even on a still die; that
    # part is allowed on top of max_span_c so only die *movement* fails the check.
    temp_noise_c: float = DEFAULT_TEMP_NOISE_C


def check_acquisition(acq: Acquisition, n_requested: int, limits: QualityLimits) -> list[str]:
    """Names of the failed checks (empty when the capture is good)."""
    failed: list[str] = []
    if acq.n != n_requested:
        failed.append("sample_count")
    if max(acq.sd_g) >= limits.sd_factor * limits.expected_sd_g:
        failed.append("noise_sd")
    if acq.sensor_c_span >= limits.max_span_c + noise_span_c(acq.n, limits.temp_noise_c):
        failed.append("temperature_span")
    if acq.saturated:
        failed.append("saturated")
    return failed


def noise_span_c(n: int, noise_c: float) -> float:
    """Typical upper range (max − min) of ``n`` Gaussian samples of rms ``noise_c``.

    E[range] ≈ 2σ·√(2 ln n); one extra σ keeps false alarms rare (≈1 % at n = 200).
    """
    if n < 2 or noise_c <= 0:
        return 0.0
    return noise_c * (2.0 * math.sqrt(2.0 * math.log(n)) + 1.0)
