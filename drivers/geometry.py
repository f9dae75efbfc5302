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

A 1-axis stage with the second axis by hand (docs/manual-fixtures.md, "One motorised
axis, one by hand") is this 2-axis convention with axis 0 on the motor and axis 1 set
by the operator, possibly only at an indexer's steps: :func:`angles_for_hand_axis`
picks, of the two poses that put a reference along gravity, one the motor and the
hand steps can take, or says why none can.

:func:`pose_quaternion` gives ``R`` itself as a unit quaternion (scalar first, ``qw ≥ 0``):
the ``pose_q*`` columns a campaign records with every reading (docs/recording.md,
"Project additions"), so a reader can test a rotation fixed in the lab frame (a tilted
table base), which the reference ``Rᵀ up`` alone cannot show (its heading about gravity
is lost).
"""

from __future__ import annotations

import math

import numpy as np

from calibration.table_pose import pose_quaternion as pose_quaternion_of


def reference_for_angles(angles_deg: tuple[float, ...] | list[float],
                         g_local: float = 1.0) -> np.ndarray:
    """Table angles (outer first, 2 or 3 axes) → specific force in the sensor frame, in g."""
    return rotation_for_angles(angles_deg).T @ np.array([0.0, 0.0, g_local])


def rotation_for_angles(angles_deg: tuple[float, ...] | list[float]) -> np.ndarray:
    """``R = Rx(a0) · Ry(a1) · Rz(a2)`` (3×3, sensor → lab) of table angles (deg, outer
    first, 2 or 3 axes; a missing inner angle is 0)."""
    if len(angles_deg) not in (2, 3):
        raise ValueError(f"expected 2 or 3 table angles, got {len(angles_deg)}")
    a = [math.radians(float(x)) for x in angles_deg] + [0.0] * (3 - len(angles_deg))
    return _rx(a[0]) @ _ry(a[1]) @ _rz(a[2])


def pose_quaternion(angles_deg: tuple[float, ...] | list[float]
                    ) -> tuple[float, float, float, float]:
    """``(qw, qx, qy, qz)``: the unit quaternion of :func:`rotation_for_angles`, scalar
    first, one spelling per rotation (``calibration.table_pose.pose_quaternion``: what the
    recordings' ``pose_q*`` columns hold), so ``Rᵀ (0, 0, 1)`` of it is
    :func:`reference_for_angles`."""
    q = pose_quaternion_of(rotation_for_angles(angles_deg))
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


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


class UnreachablePose(ValueError):
    """A reference the rig cannot put along gravity; the message says why and what would."""


#: How close (°) a hand angle must be to an indexer step to count as that step.
HAND_STEP_TOL_DEG = 0.5


def _wrap_deg(a: float) -> float:
    """An angle in (−180°, 180°]."""
    w = math.fmod(a, 360.0)
    w = w - 360.0 if w > 180.0 else w + 360.0 if w <= -180.0 else w
    return 0.0 if w == 0.0 else w


def angles_for_hand_axis(ref_g_unit: np.ndarray | tuple[float, float, float],
                         hand_steps_deg: tuple[float, ...] | None = None,
                         motor_range_deg: float = 180.0) -> tuple[float, float]:
    """``(motor, hand)`` angles (°) putting ``ref_g_unit`` along gravity on a 1-axis stage
    whose second axis (about the plate's y, inside the motor's x) is set by hand.

    The 2-axis convention has two poses for a reference, ``(a0, a1)`` and
    ``(180° − a0, a1 + 180°)``; at ``a0 = ±90°`` the hand angle is free. A pose is usable
    when ``|motor| ≤ motor_range_deg`` and the hand angle is one of ``hand_steps_deg``
    (within :data:`HAND_STEP_TOL_DEG`; ``None``: any angle). Of the usable poses the one
    with the smaller motor angle is taken; none: :class:`UnreachablePose` naming the
    angles the reference needs.
    """
    a0, a1 = angles_for_reference(ref_g_unit, 2)
    steps = None if hand_steps_deg is None else tuple(_wrap_deg(s) for s in hand_steps_deg)
    free_hand = abs(abs(a0) - 90.0) < 1e-9  # gravity along the hand axis: any hand angle
    poses = [(a0, _wrap_deg(a1)), (_wrap_deg(180.0 - a0), _wrap_deg(a1 + 180.0))]
    if free_hand and steps:
        poses = [(a0, s) for s in steps] + poses
    usable = []
    for m, h in poses:
        on_step = steps is None or any(abs(_wrap_deg(h - s)) <= HAND_STEP_TOL_DEG
                                       for s in steps)
        if abs(m) <= motor_range_deg + 1e-9 and on_step:
            snapped = h if steps is None else min(steps, key=lambda s: abs(_wrap_deg(h - s)))
            usable.append((m, snapped))
    if usable:
        m, h = min(usable, key=lambda p: abs(p[0]))
        return (0.0 if m == 0.0 else m, 0.0 if h == 0.0 else h)
    needs = " or ".join(f"motor {m:.1f}° with hand {h:.1f}°" for m, h in poses[-2:])
    why = []
    if steps is not None:
        why.append("the hand axis stops only at " + ", ".join(f"{s:g}°" for s in
                                                               hand_steps_deg or ()))
    why.append(f"the motor reaches ±{motor_range_deg:g}°")
    raise UnreachablePose(f"needs {needs}; {' and '.join(why)}")


def hand_axis_unreachable(refs_g: np.ndarray, hand_steps_deg: tuple[float, ...] | None,
                          motor_range_deg: float) -> list[tuple[int, str]]:
    """``(position, reason)`` of every schedule reference a hand-axis stage cannot reach."""
    out = []
    for i, ref in enumerate(np.asarray(refs_g, float)):
        try:
            angles_for_hand_axis(ref, hand_steps_deg, motor_range_deg)
        except UnreachablePose as exc:
            out.append((i, str(exc)))
    return out


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

