"""``temperature_sensor``: offset/nonlinearity of the temperature channel (effects.md)."""

from calibration.discrepancy.effects.not_identifiable import Unobservable

TEMPERATURE_SENSOR = Unobservable(
    effect_id="temperature_sensor", confusers=("self_heating",),
    why=("with one temperature source its offset and curvature re-map T, which the cubic "
         "in T absorbs completely"),
    experiment="log a calibrated reference thermometer on the fixture next to sensor_c",
)
