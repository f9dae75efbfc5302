"""The seed paper's 12-parameter sensor frame error model (SFEM), Eq. 1.

    U_SF = M · C · S · (U − b)                                     (Eq. 1)

* ``b``  bias vector, g (``bias_g``)
* ``S``  diagonal scale factors (dimensionless, ≈ 1)
* ``C``  lower unitriangular non-orthogonality matrix with αyx, αzx, αzy (rad)
* ``M``  misalignment rotation, three small angles about x, y, z (rad),
  ``M = Rz(ψ) · Ry(θ) · Rx(φ)``

The product ``A = M C S`` is a general 3×3 matrix with positive determinant,
so the model is equivalently ``calibrated = A · (raw − b)``: the *matrix form*
the service returns to ops. :func:`from_matrix` decomposes any such ``A``
back into (M, C, S) uniquely (a QL decomposition).

Parameter vector order (used by fits, covariances, thermal models and JSON)::

    bx by bz | sx sy sz | ayx azx azy | mx my mz
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PARAM_NAMES: tuple[str, ...] = (
    "bx", "by", "bz", "sx", "sy", "sz", "ayx", "azx", "azy", "mx", "my", "mz",
)
PARAM_UNITS: tuple[str, ...] = ("g",) * 3 + ("1",) * 3 + ("rad",) * 6
N_PARAMS = 12
BIAS = slice(0, 3)
SCALE = slice(3, 6)
ALPHA = slice(6, 9)
MISALIGN = slice(9, 12)


@dataclass(frozen=True)
class SfemParams:
    """One temperature's SFEM parameters (Eq. 1). Arrays are length-3 float arrays."""

    bias_g: np.ndarray
    scale: np.ndarray
    alpha_rad: np.ndarray  # (αyx, αzx, αzy)
    misalign_rad: np.ndarray  # (φ about x, θ about y, ψ about z)

    @classmethod
    def identity(cls) -> SfemParams:
        return cls.from_vector(identity_vector())

    @classmethod
    def from_vector(cls, p: np.ndarray) -> SfemParams:
        p = np.asarray(p, dtype=float)
        if p.shape != (N_PARAMS,):
            raise ValueError(f"SFEM parameter vector must have 12 entries, got shape {p.shape}")
        return cls(p[BIAS].copy(), p[SCALE].copy(), p[ALPHA].copy(), p[MISALIGN].copy())

    def to_vector(self) -> np.ndarray:
        return np.concatenate([self.bias_g, self.scale, self.alpha_rad, self.misalign_rad])

    def matrix(self) -> np.ndarray:
        """A = M · C · S (Eq. 1), so that calibrated = A · (raw − b)."""
        return matrix_from_vector(self.to_vector())

    def apply(self, raw_g: np.ndarray) -> np.ndarray:
        """Calibrate raw readings (N,3) or (3,): Eq. 1 forward."""
        raw = np.asarray(raw_g, dtype=float)
        return (raw - self.bias_g) @ self.matrix().T

    def invert(self, true_g: np.ndarray) -> np.ndarray:
        """Raw output that a sensor with these errors gives for specific force ``true_g``."""
        f = np.asarray(true_g, dtype=float)
        return np.linalg.solve(self.matrix(), f.T).T + self.bias_g


def identity_vector() -> np.ndarray:
    p = np.zeros(N_PARAMS)
    p[SCALE] = 1.0
    return p


def rotation(angles_rad: np.ndarray) -> np.ndarray:
    """M = Rz(ψ) · Ry(θ) · Rx(φ) for angles (φ, θ, ψ)."""
    return _rz(angles_rad[2]) @ _ry(angles_rad[1]) @ _rx(angles_rad[0])


def nonorthogonality(alpha_rad: np.ndarray) -> np.ndarray:
    """C of Eq. 1: lower unitriangular with αyx, αzx, αzy."""
    ayx, azx, azy = alpha_rad
    return np.array([[1.0, 0.0, 0.0], [ayx, 1.0, 0.0], [azx, azy, 1.0]])


def matrix_from_vector(p: np.ndarray) -> np.ndarray:
    return rotation(p[MISALIGN]) @ nonorthogonality(p[ALPHA]) @ np.diag(p[SCALE])


def from_matrix(matrix: np.ndarray, bias_g: np.ndarray) -> SfemParams:
    """Decompose A = M·C·S (rotation × lower triangular with positive diagonal).

    Uses A^T A = L^T L with L = C·S: L is the "reverse Cholesky" factor, found by
    an ordinary Cholesky of the index-reversed matrix. Requires det A > 0.
    """
    A = np.asarray(matrix, dtype=float)
    if np.linalg.det(A) <= 0:
        raise ValueError("calibration matrix must have a positive determinant")
    J = np.eye(3)[::-1]
    upper = np.linalg.cholesky(J @ A.T @ A @ J).T  # V with J AᵀA J = Vᵀ V, V upper
    L = J @ upper @ J
    R = A @ np.linalg.inv(L)
    scale = np.diag(L).copy()
    C = L / scale[None, :]
    alpha = np.array([C[1, 0], C[2, 0], C[2, 1]])
    misalign = angles_from_rotation(R)
    return SfemParams(np.asarray(bias_g, dtype=float).copy(), scale, alpha, misalign)


def angles_from_rotation(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation` (ZYX Euler angles)."""
    theta = -np.arcsin(np.clip(R[2, 0], -1.0, 1.0))
    phi = np.arctan2(R[2, 1], R[2, 2])
    psi = np.arctan2(R[1, 0], R[0, 0])
    return np.array([phi, theta, psi])


def forward_jacobian(p: np.ndarray, raw_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Calibrated output f = A(U − b) (N,3) and its Jacobian ∂f/∂p (N,3,12), analytic."""
    raw = np.asarray(raw_g, dtype=float)
    M = rotation(p[MISALIGN])
    C = nonorthogonality(p[ALPHA])
    S = np.diag(p[SCALE])
    v = raw - p[BIAS]  # (N,3)
    w = v * p[SCALE]  # S v
    u = w @ C.T  # C S v
    f = u @ M.T
    N = raw.shape[0]
    jac = np.empty((N, 3, N_PARAMS))
    A = M @ C @ S
    jac[:, :, BIAS] = -A[None, :, :]
    MC = M @ C
    for k in range(3):
        jac[:, :, 3 + k] = MC[None, :, k] * v[:, k : k + 1]
    jac[:, :, 6] = M[None, :, 1] * w[:, 0:1]  # αyx = C[1,0]
    jac[:, :, 7] = M[None, :, 2] * w[:, 0:1]  # αzx = C[2,0]
    jac[:, :, 8] = M[None, :, 2] * w[:, 1:2]  # αzy = C[2,1]
    for k, dM in enumerate(_rotation_derivatives(p[MISALIGN])):
        jac[:, :, 9 + k] = u @ dM.T
    return f, jac


def _rotation_derivatives(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    phi, theta, psi = angles
    rx, ry, rz = _rx(phi), _ry(theta), _rz(psi)
    return (rz @ ry @ _drx(phi), rz @ _dry(theta) @ rx, _drz(psi) @ ry @ rx)


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _drx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[0.0, 0.0, 0.0], [0.0, -s, -c], [0.0, c, -s]])


def _dry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[-s, 0.0, c], [0.0, 0.0, 0.0], [-c, 0.0, -s]])


def _drz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 0.0]])
