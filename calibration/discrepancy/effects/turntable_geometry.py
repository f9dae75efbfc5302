"""``turntable_geometry``: rig tilt / axis errors constant in the lab frame (effects.md)."""

from __future__ import annotations

from itertools import combinations_with_replacement

import numpy as np

from calibration import sfem
from calibration.discrepancy.effects.not_identifiable import Unobservable


def lab_to_sensor(ref_g: np.ndarray) -> np.ndarray:
    """Orientation of each position: the minimal rotation taking lab up (0,0,1) onto ``ref``.

    The fixture's commanded orientation is only known through ``ref``; this
    convention fixes the free rotation about gravity (antipode: π about x).
    """
    u = np.asarray(ref_g, float) / np.linalg.norm(ref_g, axis=1, keepdims=True)
    z = np.array([0.0, 0.0, 1.0])
    R = np.empty((u.shape[0], 3, 3))
    for i, v in enumerate(u):
        c = float(z @ v)
        if c < -1 + 1e-12:
            R[i] = np.diag([1.0, -1.0, -1.0])
            continue
        k = np.cross(z, v)
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        R[i] = np.eye(3) + K + K @ K / (1.0 + c)
    return R


def tilted_ref_g(ref_g: np.ndarray, base_tilt_rad: np.ndarray) -> np.ndarray:
    """True specific force (N,3) g on a rig whose base is tilted about lab x, y (effects.md).

    Gravity is constant in the lab frame but tilted: ``C_pos · R_tilt · up``
    instead of ``C_pos · up`` (C_pos: :func:`lab_to_sensor`), same magnitude.
    """
    tx, ty = np.asarray(base_tilt_rad, float)
    up = sfem.rotation_x(tx) @ sfem.rotation_y(ty) @ np.array([0.0, 0.0, 1.0])
    mag = np.linalg.norm(ref_g, axis=1)
    return np.einsum("nij,j->ni", lab_to_sensor(ref_g), up) * mag[:, None]


TURN_DEGREE = 2  # a_i², a_i·a_j: the catalogue nonlinearities' degree (their a³ aliases)


def turn_columns(u: np.ndarray, degree: int = TURN_DEGREE) -> np.ndarray:
    """(N,3,k): fields across the reference, ``(I − u·uᵀ)·q(u)`` for vector monomials q.

    A small rotation of the specific force ``u`` moves it across itself only. The turns
    allowed are of the catalogue nonlinearities' own polynomial degree in u: the part of a
    nonlinearity ``g(u)`` across the reference is then one of them, and what is left to
    tell it from a turn is exactly its part along the reference, ``u·g(u)``.
    """
    n = u.shape[0]
    mons = [np.ones(n)] + [np.prod(u[:, list(c)], axis=1) for d in range(1, degree + 1)
                           for c in combinations_with_replacement(range(3), d)]
    cols = []
    for m in mons:
        for a in range(3):
            q = np.zeros((n, 3))
            q[:, a] = m
            cols.append(q - np.sum(q * u, axis=1, keepdims=True) * u)
    return np.stack(cols, axis=2)


TURNTABLE_GEOMETRY = Unobservable(
    effect_id="turntable_geometry", confusers=("cross_coupling",),
    why=("the recording gives references in the sensor frame only; without the table angles a "
         "lab-frame tilt cannot be told from sensor misalignment"),
    experiment=("record the gimbal angles and repeat the tumble with the sensor remounted at 90° "
                "about the table axis (a tilt stays, misalignment turns with the sensor)"),
)
