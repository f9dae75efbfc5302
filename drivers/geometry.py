"""Turntable axis convention: table angles ↔ reference specific force in the sensor frame.

Convention (docs/registers.md, "Axis convention"):

* Lab frame: z up. A sensor at rest reads specific force ``f_lab = (0, 0, +1) g``.
* Axes are nested, outer first: axis 0 (outer) rotates about lab **x**, axis 1
  (middle) about the x-rotated **y**, axis 2 (inner, the fixture plate normal)
  about the fully rotated **z**. Positive angles are right-handed.
* At all-zero angles the sensor frame coincides with the lab frame, so the
  reference is ``(0, 0, 1)``.
* ``R = Rx(a0) · Ry(a1) · Rz(a2)`` maps sensor coordinates to lab coordinates;
  the reference in the sensor frame is ``f_s = Rᵀ f_lab``.

With the inner angle at 0, ``f_s = (−sin a1 cos a0, sin a0, cos a1 cos a0)``,
which inverts in closed form (:func:`angles_for_reference`).
"""

from __future__ import annotations

import math

import numpy as np


def reference_for_angles(angles_deg: tuple[float, ...] | list[float],
                         g_local: float = 1.0) -> np.ndarray:
    """Table angles (outer first, 2 or 3 axes) → specific force in the sensor frame, in g."""
    if len(angles_deg) not in (2, 3):
        raise ValueError(f"expected 2 or 3 table angles, got {len(angles_deg)}")
    a = [math.radians(float(x)) for x in angles_deg] + [0.0] * (3 - len(angles_deg))
    R = _rx(a[0]) @ _ry(a[1]) @ _rz(a[2])
    return R.T @ np.array([0.0, 0.0, g_local])


def angles_for_reference(ref_g_unit: np.ndarray | tuple[float, float, float],
                         n_axes: int = 3) -> tuple[float, ...]:
    """Angles (deg, outer first) that put ``ref_g_unit`` (normalised here) along gravity.

    The inner axis (3-axis tables) is left at 0°; the outer angle is in [−90°, 90°].
    """
    if n_axes not in (2, 3):
        raise ValueError(f"n_axes must be 2 or 3, got {n_axes}")
    v = np.asarray(ref_g_unit, dtype=float)
    norm = float(np.linalg.norm(v))
    if v.shape != (3,) or norm == 0.0:
        raise ValueError(f"reference must be a non-zero 3-vector, got {ref_g_unit!r}")
    x, y, z = v / norm
    a0 = math.degrees(math.asin(max(-1.0, min(1.0, y))))
    # At a0 = ±90° the middle axis is free; atan2(0, 0) = 0 picks 0°.
    a1 = math.degrees(math.atan2(-x, z)) if abs(abs(y) - 1.0) > 1e-12 else 0.0
    a1 = 0.0 if a1 == 0.0 else a1  # normalise −0.0
    return (a0, a1, 0.0) if n_axes == 3 else (a0, a1)


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def angles_for_references(refs_g: np.ndarray, n_axes: int = 3) -> np.ndarray:
    """Table angles (n, axes) of each unit gravity reference (n, 3): what the engine commands."""
    return np.array([angles_for_reference(r, n_axes) for r in np.asarray(refs_g, float)])
