"""Eq. 1 with a different parameter vector per reading (the thermal model's p(T_i), Eq. 8).

Vectorised twins of :func:`sfem.matrix_from_vector` and :func:`sfem.forward_jacobian`:
the joint thermal fit and :meth:`ThermalModel.compensate` evaluate thousands of
readings, each at its own temperature, so a Python loop per reading is too slow.
"""

from __future__ import annotations

import numpy as np

from calibration import sfem


def matrices(P: np.ndarray) -> np.ndarray:
    """A_i = M_i C_i S_i for parameter rows P (N,12): (N,3,3)."""
    M = _rotations(P[:, sfem.MISALIGN])
    return M @ _nonorth(P[:, sfem.ALPHA]) * P[:, None, sfem.SCALE]


def forward(P: np.ndarray, raw_g: np.ndarray) -> np.ndarray:
    """Calibrated f_i = A_i (U_i − b_i), (N,3)."""
    v = np.asarray(raw_g, float) - P[:, sfem.BIAS]
    return np.einsum("nij,nj->ni", matrices(P), v)


def forward_jacobian(P: np.ndarray, raw_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """f (N,3) and ∂f_i/∂p_i (N,3,12) with p_i the i-th row of P (analytic)."""
    raw = np.asarray(raw_g, float)
    ang = P[:, sfem.MISALIGN]
    M = _rotations(ang)
    C = _nonorth(P[:, sfem.ALPHA])
    s = P[:, sfem.SCALE]
    v = raw - P[:, sfem.BIAS]
    w = v * s
    u = np.einsum("nij,nj->ni", C, w)
    f = np.einsum("nij,nj->ni", M, u)
    N = raw.shape[0]
    jac = np.empty((N, 3, sfem.N_PARAMS))
    MC = M @ C
    jac[:, :, sfem.BIAS] = -MC * s[:, None, :]
    for k in range(3):
        jac[:, :, 3 + k] = MC[:, :, k] * v[:, k : k + 1]
    jac[:, :, 6] = M[:, :, 1] * w[:, 0:1]
    jac[:, :, 7] = M[:, :, 2] * w[:, 0:1]
    jac[:, :, 8] = M[:, :, 2] * w[:, 1:2]
    rx, ry, rz = _rx(ang[:, 0]), _ry(ang[:, 1]), _rz(ang[:, 2])
    drx, dry, drz = _rx(ang[:, 0], d=True), _ry(ang[:, 1], d=True), _rz(ang[:, 2], d=True)
    for k, dM in enumerate((rz @ ry @ drx, rz @ dry @ rx, drz @ ry @ rx)):
        jac[:, :, 9 + k] = np.einsum("nij,nj->ni", dM, u)
    return f, jac


def _rotations(ang: np.ndarray) -> np.ndarray:
    return _rz(ang[:, 2]) @ _ry(ang[:, 1]) @ _rx(ang[:, 0])


def _nonorth(alpha: np.ndarray) -> np.ndarray:
    C = np.zeros((alpha.shape[0], 3, 3))
    C[:, 0, 0] = C[:, 1, 1] = C[:, 2, 2] = 1.0
    C[:, 1, 0], C[:, 2, 0], C[:, 2, 1] = alpha[:, 0], alpha[:, 1], alpha[:, 2]
    return C


def _rot(a: np.ndarray, i: int, j: int, k: int, d: bool, sign: float) -> np.ndarray:
    """Rotation about axis k (i, j the other two) or its derivative; sign picks Ry's layout."""
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((a.size, 3, 3))
    if d:
        R[:, i, i], R[:, j, j] = -s, -s
        R[:, i, j], R[:, j, i] = -sign * c, sign * c
    else:
        R[:, k, k] = 1.0
        R[:, i, i], R[:, j, j] = c, c
        R[:, i, j], R[:, j, i] = -sign * s, sign * s
    return R


def _rx(a: np.ndarray, d: bool = False) -> np.ndarray:
    return _rot(a, 1, 2, 0, d, 1.0)


def _ry(a: np.ndarray, d: bool = False) -> np.ndarray:
    return _rot(a, 0, 2, 1, d, -1.0)


def _rz(a: np.ndarray, d: bool = False) -> np.ndarray:
    return _rot(a, 0, 1, 2, d, 1.0)
