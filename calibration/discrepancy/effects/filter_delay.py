"""``filter_delay``: timestamp lag of the digital filter (effects.md)."""

from __future__ import annotations

import numpy as np

from calibration.discrepancy.effects.not_identifiable import Unobservable


def delayed_input_shift_g(omega_rad_s: np.ndarray, ref_g: np.ndarray,
                          delay_s: float) -> np.ndarray:
    """Input change (N,3) g when each sample is the input ``delay_s`` earlier (effects.md).

    Gravity in a frame rotating at ω moves as ``dref/dt = −ω × ref``, so the
    delayed input is ``ref + delay_s · ω × ref``: tangential, ∝ ω, sign flips with
    the direction of rotation.
    """
    return delay_s * np.cross(np.asarray(omega_rad_s, float), ref_g)

FILTER_DELAY = Unobservable(
    effect_id="filter_delay", confusers=("lever_arm",), needs_motion=True,
    why=("it acts only while the table rotates (∝ ω, sign flips with direction); "
         "readings are static"),
    experiment="record continuous rotations in both directions and compare the tangential error",
)
