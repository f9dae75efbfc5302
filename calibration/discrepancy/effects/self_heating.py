"""``self_heating``: the die runs warmer than the chamber (effects.md)."""

from __future__ import annotations

import numpy as np

from calibration.discrepancy.effects.not_identifiable import Unobservable


def warmup_delta_c(age_s: np.ndarray, delta_c: float, warmup_tau_s: float) -> np.ndarray:
    """Die temperature above the chamber (N,) °C, ``age_s`` (N,) s after power-on.

    ``ΔT = delta_c · (1 − exp(−age/warmup_tau_s))`` (effects.md); ``warmup_tau_s ≤ 0``
    is an instant warm-up (ΔT = delta_c throughout); negative ages count as 0.
    """
    age = np.asarray(age_s, float)
    if warmup_tau_s <= 0:
        return np.full(age.shape, float(delta_c))
    return delta_c * (1.0 - np.exp(-np.clip(age, 0.0, None) / warmup_tau_s))

SELF_HEATING = Unobservable(
    effect_id="self_heating", confusers=("temperature_sensor", "thermal_lag"),
    why=("a steady die-above-chamber offset is a shift of temperature that the cubic absorbs, "
         "and sensor_c is not absolute, so its offset is the same signature"),
    experiment=("power the sensor on at a constant chamber temperature and log output and "
                "sensor_c through the warm-up, or read the package with a reference probe"),
)
