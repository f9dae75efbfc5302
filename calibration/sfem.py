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
back into (M, C, S) uniquely (a QL decomposition); :func:`vector_from_matrix` does the
same for a stack of matrices.

Parameter vector order (used by fits, covariances, thermal models and JSON)::

    bx by bz | sx sy sz | ayx azx azy | mx my mz

Eq. 1 is written once, here: :func:`rotation` (and its factors :func:`rotation_x`,
:func:`rotation_y`, :func:`rotation_z`), :func:`nonorthogonality`,
:func:`matrix_from_vector`, :func:`forward`, :func:`inverse` and the analytic
:func:`forward_jacobian` take one parameter vector (12,) or one per reading (N,12) — the
thermal model's p(T_i) of Eq. 8, which the joint fits and compensation evaluate for
thousands of readings at once; :func:`forward` also takes one vector per problem (K,12)
for K problems' readings (K,N,3). :func:`coefficient_jacobian` chains the Jacobian through
Eq. 8, :func:`norm_jacobian` projects it for norm mode (Eq. 3) and :func:`norm_sigma` gives
that residual's σ.
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
        return forward(self.to_vector(), raw_g)

    def invert(self, true_g: np.ndarray) -> np.ndarray:
        """Raw output that a sensor with these errors gives for specific force ``true_g``."""
        return inverse(self.to_vector(), true_g)


def identity_vector() -> np.ndarray:
    p = np.zeros(N_PARAMS)
    p[SCALE] = 1.0
    return p


def rotation(angles_rad: np.ndarray) -> np.ndarray:
    """M = Rz(ψ) · Ry(θ) · Rx(φ) of Eq. 1 for angles (φ, θ, ψ): (3,) → (3,3), (N,3) → (N,3,3)."""
    ang = np.asarray(angles_rad, dtype=float)
    return rotation_z(ang[..., 2]) @ rotation_y(ang[..., 1]) @ rotation_x(ang[..., 0])


def rotation_x(a: np.ndarray | float, d: bool = False) -> np.ndarray:
    """Rx(a), a right-handed rotation about x by angles ``a`` (…): (…,3,3); ∂Rx/∂a if ``d``."""
    return _rot(a, 1, 2, 0, d, 1.0)


def rotation_y(a: np.ndarray | float, d: bool = False) -> np.ndarray:
    """Ry(a) about y (…,3,3); ∂Ry/∂a if ``d``."""
    return _rot(a, 0, 2, 1, d, -1.0)


def rotation_z(a: np.ndarray | float, d: bool = False) -> np.ndarray:
    """Rz(a) about z (…,3,3); ∂Rz/∂a if ``d``."""
    return _rot(a, 0, 1, 2, d, 1.0)


def nonorthogonality(alpha_rad: np.ndarray) -> np.ndarray:
    """C of Eq. 1: lower unitriangular with αyx, αzx, αzy. (3,) → (3,3), (N,3) → (N,3,3)."""
    alpha = np.asarray(alpha_rad, dtype=float)
    C = np.zeros(alpha.shape[:-1] + (3, 3))
    C[..., 0, 0] = C[..., 1, 1] = C[..., 2, 2] = 1.0
    C[..., 1, 0], C[..., 2, 0], C[..., 2, 1] = alpha[..., 0], alpha[..., 1], alpha[..., 2]
    return C


def matrix_from_vector(p: np.ndarray) -> np.ndarray:
    """A = M · C · S of Eq. 1 for one parameter vector (12,) → (3,3), or rows (N,12) → (N,3,3)."""
    p = np.asarray(p, dtype=float)
    return rotation(p[..., MISALIGN]) @ nonorthogonality(p[..., ALPHA]) * p[..., None, SCALE]


def from_matrix(matrix: np.ndarray, bias_g: np.ndarray) -> SfemParams:
    """Decompose A = M·C·S (rotation × lower triangular with positive diagonal).

    Uses A^T A = L^T L with L = C·S: L is the "reverse Cholesky" factor, found by
    an ordinary Cholesky of the index-reversed matrix. Requires det A > 0.
    """
    A = np.asarray(matrix, dtype=float)
    if np.linalg.det(A) <= 0:
        raise ValueError("calibration matrix must have a positive determinant")
    return SfemParams.from_vector(vector_from_matrix(A, bias_g))


def vector_from_matrix(matrix: np.ndarray, bias_g: np.ndarray) -> np.ndarray:
    """:func:`from_matrix` as parameter vectors: A (3,3) and b (3,) → (12,), or a stack
    A (K,3,3) and b (K,3) → (K,12) (the batched fits). det A > 0 is the caller's to check:
    for det A ≤ 0 the Cholesky fails or the angles are meaningless."""
    A = np.asarray(matrix, dtype=float)
    J = np.eye(3)[::-1]
    upper = np.swapaxes(np.linalg.cholesky(J @ np.swapaxes(A, -1, -2) @ A @ J), -1, -2)
    L = J @ upper @ J  # J AᵀA J = Vᵀ V with V upper: L = J V J is lower, AᵀA = Lᵀ L
    R = A @ np.linalg.inv(L)
    scale = np.diagonal(L, axis1=-2, axis2=-1)
    C = L / scale[..., None, :]
    p = np.empty(A.shape[:-2] + (N_PARAMS,))
    p[..., BIAS] = bias_g
    p[..., SCALE] = scale
    p[..., ALPHA] = np.stack([C[..., 1, 0], C[..., 2, 0], C[..., 2, 1]], axis=-1)
    p[..., MISALIGN] = angles_from_rotation(R)
    return p


def angles_from_rotation(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation` (ZYX Euler angles): (3,3) → (3,), (K,3,3) → (K,3)."""
    theta = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    phi = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    psi = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([phi, theta, psi], axis=-1)


def forward(p: np.ndarray, raw_g: np.ndarray) -> np.ndarray:
    """Calibrated output f = A (U − b) of Eq. 1, (N,3), for raw readings U (N,3).

    ``p`` is one parameter vector (12,) for every reading, or one per reading (N,12),
    e.g. the thermal model's p(T_i) of Eq. 8. When ``raw_g`` has one axis more than
    ``p``, each vector serves a whole set of readings: p (K,12) with U (K,N,3) is K
    problems' readings (the batched fits), f (K,N,3).
    """
    p = np.asarray(p, dtype=float)
    raw = np.asarray(raw_g, dtype=float)
    bias = p[..., BIAS]
    if p.ndim > 1 and raw.ndim == p.ndim + 1:
        bias = bias[..., None, :]  # one vector per set of readings
    return _apply(matrix_from_vector(p), raw - bias)


def inverse(p: np.ndarray, calibrated_g: np.ndarray) -> np.ndarray:
    """Raw output U = A⁻¹ f + b that Eq. 1 maps onto ``calibrated_g`` f (…,3): what a sensor
    with these errors reads for the specific force f (the twin's sensor, synthetic data).

    ``p`` as in :func:`forward`: one vector (12,) for all rows, or one per row (N,12)
    (more leading axes broadcast against f's, e.g. (K,1,12) with (K,N,3)).
    """
    p = np.asarray(p, dtype=float)
    f = np.asarray(calibrated_g, dtype=float)
    A = matrix_from_vector(p)
    if A.ndim == 2:
        return np.linalg.solve(A, f.T).T + p[BIAS]  # one factorisation for all rows
    return np.linalg.solve(A, f[..., None])[..., 0] + p[..., BIAS]


def forward_jacobian(p: np.ndarray, raw_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """f = A (U − b) of Eq. 1 (N,3) and its analytic Jacobian ∂f_i/∂p (N,3,12).

    The Jacobian is what Levenberg–Marquardt (Eq. 7) and every linearised test use.
    ``p`` is one vector (12,) for all N readings, or one per reading (N,12): then row i
    of the Jacobian is the derivative in reading i's own parameters (the joint thermal
    fit chains it with the powers of Eq. 8).
    """
    p = np.asarray(p, dtype=float)
    raw = np.asarray(raw_g, dtype=float)
    ang = p[..., MISALIGN]
    M = rotation(ang)
    C = nonorthogonality(p[..., ALPHA])
    s = p[..., SCALE]
    v = raw - p[..., BIAS]  # (N,3)
    w = v * s  # S v
    u = _apply(C, w)  # C S v
    f = _apply(M, u)
    jac = np.empty((raw.shape[0], 3, N_PARAMS))
    MC = M @ C
    jac[:, :, BIAS] = -MC * s[..., None, :]  # −A
    for k in range(3):
        jac[:, :, 3 + k] = MC[..., :, k] * v[:, k : k + 1]
    jac[:, :, 6] = M[..., :, 1] * w[:, 0:1]  # αyx = C[1,0]
    jac[:, :, 7] = M[..., :, 2] * w[:, 0:1]  # αzx = C[2,0]
    jac[:, :, 8] = M[..., :, 2] * w[:, 1:2]  # αzy = C[2,1]
    for k, dM in enumerate(_rotation_derivatives(ang)):
        jac[:, :, 9 + k] = _apply(dM, u)
    return f, jac


def norm_jacobian(f: np.ndarray, jac: np.ndarray) -> np.ndarray:
    """∂|f_i|/∂q of norm mode (Eq. 3): (f_i/|f_i|)·∂f_i/∂q for f (N,3), ∂f/∂q (N,3,K): (N,K)."""
    unit = f / np.linalg.norm(f, axis=1)[:, None]
    return np.einsum("ni,nik->nk", unit, jac)


def norm_sigma(f: np.ndarray, sigma_g: np.ndarray) -> np.ndarray:
    """σ of |f_i| (N,) from per-axis σ (N,3) of f (N,3): the norm-mode residual's (Eq. 3).

    To first order |f| moves with the component along f's direction û, so
    σ_|f| = √(Σ_a (û_a σ_a)²): the weight of every norm-mode fit (per step, joint,
    hand-placed) and of the model floor's norm residuals.
    """
    unit = f / np.linalg.norm(f, axis=1)[:, None]
    return np.sqrt(np.sum((unit * sigma_g) ** 2, axis=1))


def coefficient_jacobian(
    jac: np.ndarray, powers: np.ndarray, cols: np.ndarray | None = None
) -> np.ndarray:
    """Chain rule through Eq. 8, ``p_k(T_i) = Σ_j c_kj x_i^j``: ∂/∂c_kj = ∂/∂p_k · x_i^j.

    ``jac`` (N,…,K): a derivative in each reading's parameters (from :func:`forward_jacobian`,
    :func:`norm_jacobian`, or a weighted form); ``powers`` (N,d+1): ``x_i^j``. With
    ``cols`` (m,2) of (k, j) pairs the result is (N,…,m); without, every k × every j,
    k-major: (N,…,K·(d+1)).
    """
    x = powers.reshape(powers.shape[:1] + (1,) * (jac.ndim - 2) + powers.shape[1:])
    if cols is not None:
        return jac[..., cols[:, 0]] * x[..., cols[:, 1]]
    return (jac[..., :, None] * x[..., None, :]).reshape(jac.shape[:-1] + (-1,))


def _apply(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x for every row of x (N,3): one matrix (3,3) for all rows, or one per row (N,3,3);
    or one matrix per set of rows, A (K,3,3) for x (K,N,3)."""
    if A.ndim == 2 or A.ndim == x.ndim:
        # One BLAS product for all rows (of each set): fastest, and the bits the
        # per-temperature fits have always had (einsum's sum order differs in the last bit).
        return x @ np.swapaxes(A, -1, -2)
    return np.einsum("nij,nj->ni", A, x)


def _rotation_derivatives(ang: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """∂M/∂φ, ∂M/∂θ, ∂M/∂ψ for angles (…,3)."""
    phi, theta, psi = ang[..., 0], ang[..., 1], ang[..., 2]
    rx, ry, rz = rotation_x(phi), rotation_y(theta), rotation_z(psi)
    return (
        rz @ ry @ rotation_x(phi, d=True),
        rz @ rotation_y(theta, d=True) @ rx,
        rotation_z(psi, d=True) @ ry @ rx,
    )


def _rot(a: np.ndarray, i: int, j: int, k: int, d: bool, sign: float) -> np.ndarray:
    """Rotation by angles ``a`` (…) about axis k (i, j the other two), or its derivative
    in ``a`` when ``d``: (…,3,3). ``sign`` = −1 gives Ry's layout (sin above the diagonal)."""
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(np.shape(a) + (3, 3))
    if d:
        R[..., i, i], R[..., j, j] = -s, -s
        R[..., i, j], R[..., j, i] = -sign * c, sign * c
    else:
        R[..., k, k] = 1.0
        R[..., i, i], R[..., j, j] = c, c
        R[..., i, j], R[..., j, i] = -sign * s, sign * s
    return R
