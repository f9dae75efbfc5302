"""One module per catalogue effect (docs/effects.md), all with the CatalogueEffect interface."""

from calibration.discrepancy.effects.base import CatalogueEffect
from calibration.discrepancy.effects.bias_drift import BiasDrift
from calibration.discrepancy.effects.cross_coupling import CrossCoupling
from calibration.discrepancy.effects.filter_delay import FILTER_DELAY
from calibration.discrepancy.effects.lever_arm import LEVER_ARM
from calibration.discrepancy.effects.local_gravity import LOCAL_GRAVITY
from calibration.discrepancy.effects.outlier import Outlier
from calibration.discrepancy.effects.scale_nonlinearity import ScaleNonlinearity
from calibration.discrepancy.effects.self_heating import SELF_HEATING
from calibration.discrepancy.effects.session_offset import SessionOffset
from calibration.discrepancy.effects.temperature_rate import TemperatureRate
from calibration.discrepancy.effects.temperature_sensor import TemperatureSensor
from calibration.discrepancy.effects.thermal_hysteresis import ThermalHysteresis
from calibration.discrepancy.effects.thermal_lag import ThermalLag
from calibration.discrepancy.effects.turntable_geometry import TURNTABLE_GEOMETRY
from calibration.discrepancy.effects.vibration_rectification import VibrationRectification

ALL_EFFECTS: tuple[CatalogueEffect, ...] = (
    Outlier(), ThermalLag(), ThermalHysteresis(), ScaleNonlinearity(), BiasDrift(),
    SessionOffset(), TemperatureRate(), CrossCoupling(), VibrationRectification(),
    TemperatureSensor(), SELF_HEATING, TURNTABLE_GEOMETRY, LEVER_ARM, FILTER_DELAY, LOCAL_GRAVITY,
)
BY_ID: dict[str, CatalogueEffect] = {e.effect_id: e for e in ALL_EFFECTS}

__all__ = ["ALL_EFFECTS", "BY_ID", "CatalogueEffect"]
