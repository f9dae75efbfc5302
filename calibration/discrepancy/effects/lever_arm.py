"""``lever_arm``: centripetal acceleration off the rotation axis (effects.md)."""

from __future__ import annotations

import numpy as np

from calibration.discrepancy.effects.not_identifiable import Unobservable
from calibration.gravity import STANDARD_GRAVITY_M_S2


def centripetal_g(omega_rad_s: np.ndarray, r_m: np.ndarray) -> np.ndarray:
    """Centripetal specific force ``ω × (ω × r) / g0`` in g (effects.md).

    ``omega_rad_s`` (N,3) or (3,) rad/s in the sensor frame, ``r_m`` (3,) m the
    sensor's offset from the rotation axis; constant rate, so no tangential term.
    """
    w = np.asarray(omega_rad_s, float)
    r = np.broadcast_to(np.asarray(r_m, float), (3,)).copy()
    return np.cross(w, np.cross(w, r[None, :])) / STANDARD_GRAVITY_M_S2

LEVER_ARM = Unobservable(
    effect_id="lever_arm", confusers=("filter_delay",), needs_motion=True,
    why="it acts only while the table rotates (∝ ω²); every reading here is static",
    experiment="record during constant-rate rotations at two or more rates (e.g. 60 and 120 °/s)",
)
