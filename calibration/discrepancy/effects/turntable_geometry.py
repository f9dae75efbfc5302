"""``turntable_geometry``: rig tilt / axis errors constant in the lab frame (effects.md)."""

from calibration.discrepancy.effects.not_identifiable import Unobservable

TURNTABLE_GEOMETRY = Unobservable(
    effect_id="turntable_geometry", confusers=("cross_coupling",),
    why=("the recording gives references in the sensor frame only; without the table angles a "
         "lab-frame tilt cannot be told from sensor misalignment"),
    experiment=("record the gimbal angles and repeat the tumble with the sensor remounted at 90° "
                "about the table axis (a tilt stays, misalignment turns with the sensor)"),
)
