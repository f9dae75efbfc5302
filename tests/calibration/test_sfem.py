"""The SFEM algebra of Eq. 1: parametrisation, matrix form, decomposition, Jacobian."""

import numpy as np
import pytest

from calibration import sfem


def _random_params(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p = sfem.identity_vector()
    p[sfem.BIAS] = rng.uniform(-0.03, 0.03, 3)
    p[sfem.SCALE] += rng.normal(0, 0.01, 3)
    p[sfem.ALPHA] = rng.normal(0, 0.005, 3)
    p[sfem.MISALIGN] = rng.normal(0, 0.01, 3)
    return p


@pytest.mark.parametrize("seed", range(5))
def test_matrix_form_decomposes_back_to_the_twelve_parameters(seed: int) -> None:
    p = _random_params(seed)
    params = sfem.SfemParams.from_vector(p)
    back = sfem.from_matrix(params.matrix(), params.bias_g)
    np.testing.assert_allclose(back.to_vector(), p, atol=1e-12)


def test_matrix_is_m_c_s_in_that_order() -> None:
    p = _random_params(7)
    M = sfem.rotation(p[sfem.MISALIGN])
    C = sfem.nonorthogonality(p[sfem.ALPHA])
    S = np.diag(p[sfem.SCALE])
    np.testing.assert_allclose(sfem.matrix_from_vector(p), M @ C @ S)
    assert np.allclose(C, np.tril(C)) and np.allclose(np.diag(C), 1.0)
    np.testing.assert_allclose(M @ M.T, np.eye(3), atol=1e-15)


def test_invert_is_the_inverse_of_apply() -> None:
    params = sfem.SfemParams.from_vector(_random_params(3))
    f = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_allclose(params.apply(params.invert(f)), f, atol=1e-13)


def test_identity_leaves_readings_unchanged() -> None:
    f = np.random.default_rng(1).normal(size=(4, 3))
    np.testing.assert_allclose(sfem.SfemParams.identity().apply(f), f)


def test_analytic_jacobian_matches_finite_differences() -> None:
    p = _random_params(11)
    raw = np.random.default_rng(2).normal(size=(6, 3))
    f0, jac = sfem.forward_jacobian(p, raw)
    eps = 1e-6
    for k in range(sfem.N_PARAMS):
        d = p.copy()
        d[k] += eps
        f1, _ = sfem.forward_jacobian(d, raw)
        np.testing.assert_allclose(
            jac[:, :, k], (f1 - f0) / eps, atol=5e-6, err_msg=sfem.PARAM_NAMES[k]
        )


def test_decomposition_refuses_a_reflection() -> None:
    with pytest.raises(ValueError, match="positive determinant"):
        sfem.from_matrix(np.diag([1.0, 1.0, -1.0]), np.zeros(3))


def test_vector_length_is_checked() -> None:
    with pytest.raises(ValueError, match="12 entries"):
        sfem.SfemParams.from_vector(np.zeros(9))


def _textbook_rotation(phi: float, theta: float, psi: float) -> np.ndarray:
    """Rz(ψ)·Ry(θ)·Rx(φ) multiplied out by hand (ZYX Euler angles), independent of sfem."""
    cf, sf, ct, st, cp, sp = (np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta),
                              np.cos(psi), np.sin(psi))
    return np.array([
        [cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf],
        [sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf],
        [-st, ct * sf, ct * cf],
    ])


def test_rotation_of_one_or_many_angle_triples_is_the_zyx_product() -> None:
    ang = np.random.default_rng(4).uniform(-1.2, 1.2, (7, 3))  # large: every term shows
    many = sfem.rotation(ang)
    assert many.shape == (7, 3, 3)
    for i, a in enumerate(ang):
        want = _textbook_rotation(*a)
        np.testing.assert_allclose(sfem.rotation(a), want, atol=1e-15)
        np.testing.assert_allclose(many[i], want, atol=1e-15)
        np.testing.assert_allclose(sfem.angles_from_rotation(many[i]), a, atol=1e-12)


def test_per_reading_parameters_give_each_reading_its_own_model_and_jacobian() -> None:
    """Rows of p (the thermal model's p(T_i)): f_i and ∂f_i/∂p_i against an independent
    per-reading evaluation and central differences, at large angles."""
    rng = np.random.default_rng(5)
    P = np.stack([_random_params(20 + i) for i in range(5)])
    P[:, sfem.MISALIGN] = rng.uniform(-0.8, 0.8, (5, 3))
    P[:, sfem.ALPHA] = rng.uniform(-0.2, 0.2, (5, 3))
    raw = rng.normal(size=(5, 3))
    f, jac = sfem.forward_jacobian(P, raw)
    for i in range(5):
        C = np.eye(3)
        C[1, 0], C[2, 0], C[2, 1] = P[i, sfem.ALPHA]
        A = _textbook_rotation(*P[i, sfem.MISALIGN]) @ C @ np.diag(P[i, sfem.SCALE])
        np.testing.assert_allclose(sfem.matrix_from_vector(P)[i], A, atol=1e-15)
        np.testing.assert_allclose(f[i], A @ (raw[i] - P[i, sfem.BIAS]), atol=1e-14)
    np.testing.assert_allclose(sfem.forward(P, raw), f, atol=0)
    h = 1e-6
    for k in range(sfem.N_PARAMS):
        up, down = P.copy(), P.copy()
        up[:, k] += h
        down[:, k] -= h
        fd = (sfem.forward(up, raw) - sfem.forward(down, raw)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], fd, atol=1e-9, err_msg=sfem.PARAM_NAMES[k])


def test_coefficient_and_norm_jacobians_match_finite_differences_of_the_thermal_model() -> None:
    """Eq. 1 with Eq. 8's p_k(T) = Σ_j c_kj x^j: the chained Jacobian in the coefficients
    (all of them, and a chosen (k, j) subset), and norm mode's ∂|f|/∂c (Eq. 3)."""
    rng = np.random.default_rng(6)
    n, deg = 9, 3
    coeffs = np.zeros((sfem.N_PARAMS, deg + 1))
    coeffs[:, 0] = _random_params(30)
    coeffs[:, 1:] = rng.normal(0.0, 0.01, (sfem.N_PARAMS, deg))
    x = rng.uniform(-1.0, 1.0, n)
    V = np.vander(x, deg + 1, increasing=True)
    raw = rng.normal(size=(n, 3))

    def f_of(c: np.ndarray) -> np.ndarray:
        return sfem.forward(V @ c.T, raw)

    f, jac = sfem.forward_jacobian(V @ coeffs.T, raw)
    full = sfem.coefficient_jacobian(jac, V)  # (n, 3, 12·(d+1)), k-major
    cols = np.array([[0, 0], [4, 2], [10, 3], [7, 1]])
    some = sfem.coefficient_jacobian(jac, V, cols)
    dnorm = sfem.norm_jacobian(f, full)
    h = 1e-6
    for k in range(sfem.N_PARAMS):
        for j in range(deg + 1):
            up, down = coeffs.copy(), coeffs.copy()
            up[k, j] += h
            down[k, j] -= h
            fd = (f_of(up) - f_of(down)) / (2 * h)
            col = k * (deg + 1) + j
            np.testing.assert_allclose(full[:, :, col], fd, atol=1e-9, err_msg=f"c[{k},{j}]")
            fd_norm = (np.linalg.norm(f_of(up), axis=1) - np.linalg.norm(f_of(down), axis=1)) / (
                2 * h
            )
            np.testing.assert_allclose(dnorm[:, col], fd_norm, atol=1e-9, err_msg=f"|f| c[{k},{j}]")
    for m, (k, j) in enumerate(cols):
        np.testing.assert_array_equal(some[:, :, m], full[:, :, k * (deg + 1) + j])


def test_a_stack_of_matrices_decomposes_like_each_one_alone() -> None:
    """vector_from_matrix (the batched fits' decomposition) on K matrices: each row is
    from_matrix's, and rebuilds its A and b."""
    P = np.stack([_random_params(50 + k) for k in range(6)])
    A = sfem.matrix_from_vector(P)
    got = sfem.vector_from_matrix(A, P[:, sfem.BIAS])
    assert got.shape == (6, 12)
    np.testing.assert_allclose(got, P, atol=1e-12)
    for k in range(6):
        one = sfem.from_matrix(A[k], P[k, sfem.BIAS]).to_vector()
        np.testing.assert_allclose(got[k], one, rtol=0, atol=1e-15)
        np.testing.assert_allclose(sfem.vector_from_matrix(A[k], P[k, sfem.BIAS]), one, atol=0)


def test_forward_with_one_vector_per_problem_evaluates_each_problems_readings() -> None:
    """p (K,12) with readings (K,N,3): problem k's readings through its own vector only.
    K = N = 3, where subtracting (K,3) biases from (K,N,3) readings without the extra axis
    would broadcast silently across the wrong axis."""
    rng = np.random.default_rng(8)
    P = np.stack([_random_params(40 + k) for k in range(3)])
    raw = rng.normal(size=(3, 3, 3))
    f = sfem.forward(P, raw)
    assert f.shape == (3, 3, 3)
    for k in range(3):
        np.testing.assert_allclose(f[k], sfem.forward(P[k], raw[k]), rtol=0, atol=1e-15)
        A = sfem.matrix_from_vector(P[k])
        np.testing.assert_allclose(f[k], (raw[k] - P[k, sfem.BIAS]) @ A.T, atol=1e-15)


def test_norm_sigma_projects_the_per_axis_sigma_on_the_readings_direction() -> None:
    """σ of |f| (Eq. 3's residual): the axis's own σ along an axis, the quadrature mean
    on a diagonal, and the spread of |f| under small per-axis noise (Monte Carlo)."""
    sig = np.array([[1e-4, 2e-4, 4e-4]] * 4)
    f = np.array([[0.0, 0.0, -1.0], [0.0, 2.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 1.0]])
    got = sfem.norm_sigma(f, sig)
    np.testing.assert_allclose(got[:3], [4e-4, 2e-4, np.sqrt((1e-8 + 4e-8) / 2)], rtol=1e-12)
    rng = np.random.default_rng(9)
    noisy = f[3] + rng.normal(size=(200_000, 3)) * sig[3]
    assert got[3] == pytest.approx(np.std(np.linalg.norm(noisy, axis=1)), rel=0.01)


def test_elementary_rotations_and_their_derivatives() -> None:
    a = np.array([-1.1, 0.0, 0.4, 2.5])
    for i, r in enumerate((sfem.rotation_x, sfem.rotation_y, sfem.rotation_z)):
        R = r(a)
        for m, ang in enumerate(a):
            want = _textbook_rotation(*(ang if q == i else 0.0 for q in range(3)))
            np.testing.assert_allclose(R[m], want, atol=1e-15)
            np.testing.assert_allclose(r(float(ang)), want, atol=1e-15)
        h = 1e-6
        np.testing.assert_allclose(r(a, d=True), (r(a + h) - r(a - h)) / (2 * h), atol=1e-9)
