"""Shared simulated campaigns for the thermal-model tests (small, deterministic)."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import Polynomial

from calibration.recording import Recording
from simulators.campaign_sim import simulate_campaign
from simulators.truth import T_REF_C, SensorTruth


def truth(seed: int = 3, offset_c: float = 0.0) -> SensorTruth:
    t = SensorTruth.adxl355_typical(seed)
    t.temp_offset_c = offset_c  # the sensor channel reads the die temperature exactly
    return t


def campaign(seed: int = 3, setpoints: tuple[float, ...] | None = None,
             **kw: object) -> tuple[SensorTruth, Recording]:
    t = truth(seed)
    sp = setpoints or tuple(float(v) for v in range(-40, 61, 10))
    return t, simulate_campaign(t, sp, seed=seed + 1000, **kw)  # type: ignore[return-value]


def truth_coeffs_in_x(t: SensorTruth, centre_c: float, scale_c: float) -> np.ndarray:
    """The truth's cubic coefficients re-expressed in x = (T − centre)/scale, (12, 4)."""
    q = Polynomial([centre_c - T_REF_C, scale_c])
    out = np.zeros((12, 4))
    for k in range(12):
        c = Polynomial(t.coeffs[k])(q).coef
        out[k, : c.size] = c
    return out
