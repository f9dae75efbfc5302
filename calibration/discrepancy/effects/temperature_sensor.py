"""``temperature_sensor``: offset/nonlinearity of the temperature channel (effects.md)."""

from __future__ import annotations

import numpy as np

from calibration.discrepancy.effects.not_identifiable import Unobservable

T_REF_SENSOR_C = 25.0  # the channel's curvature is about room temperature (effects.md)


def channel_error_c(die_c: np.ndarray, offset_c: float, k2_per_c: float) -> np.ndarray:
    """Temperature-channel error (N,) °C: ``offset_c + k2_per_c · (T_die − 25)²`` (effects.md)."""
    return offset_c + k2_per_c * (np.asarray(die_c, float) - T_REF_SENSOR_C) ** 2

TEMPERATURE_SENSOR = Unobservable(
    effect_id="temperature_sensor", confusers=("self_heating",),
    why=("with one temperature source its offset and curvature re-map T, which the cubic "
         "in T absorbs completely"),
    experiment="log a calibrated reference thermometer on the fixture next to sensor_c",
)
