"""``self_heating``: the die runs warmer than the chamber (effects.md)."""

from calibration.discrepancy.effects.not_identifiable import Unobservable

SELF_HEATING = Unobservable(
    effect_id="self_heating", confusers=("temperature_sensor", "thermal_lag"),
    why=("a steady die-above-chamber offset is a shift of temperature that the cubic absorbs, "
         "and sensor_c is not absolute, so its offset is the same signature"),
    experiment=("power the sensor on at a constant chamber temperature and log output and "
                "sensor_c through the warm-up, or read the package with a reference probe"),
)
