"""Each test behind the verdict "mismatch" runs at its nominal level (issue 22).

The verdict is the union of the forward selection's family test and the localised scan,
each at α/2; a null recording is "mismatch" only through one of them. These tests pin the
level of the pieces whose null is not a plain Gaussian bootstrap.
"""

import importlib
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats as sps

from calibration.discrepancy import stats


def _mixture_readings(rng, n, g, nu, B):
    """B recordings of n readings whose g entries share one Student-t scale (ν) each."""
    row = np.repeat(np.arange(n), g)
    w = np.sqrt(nu / rng.chisquare(nu, (n, B)))
    return row, rng.standard_normal((n * g, B)) * w[row]


@pytest.mark.parametrize("nu", [5.0, 8.0])
def test_student_t_null_of_the_outlier_test_is_at_its_level(nu):
    """The max over readings of t-mixture recordings, scored against row_stats' mixed null,
    is flagged at the nominal rate (the earlier null, w·k instead of w/k, ran at ~half)."""
    rng = np.random.default_rng(11)
    n, g, B = 120, 3, 1000
    row, data = _mixture_readings(rng, n, g, nu, B)
    U = np.zeros((n * g, 0))
    s_data = stats.robust_scale(data, 1.0)
    E = rng.standard_normal((n * g, B))
    s_null = stats.robust_scale(E, 1.0)
    _, null_max, _ = stats.row_stats(U, data[:, 0], E, row, n, s_data[0], s_null, set(), None,
                                     nu, np.random.default_rng(12))
    data_max = np.array([stats.row_stats(U, data[:, b], E[:, :1], row, n, s_data[b],
                                         s_null[:1], set())[0].max() for b in range(B)])
    p = (1 + (null_max[None, :] >= data_max[:, None]).sum(1)) / (B + 1)
    # binomial sd at 1000 draws: 0.7 % at 5 %, 0.95 % at 10 %
    assert np.mean(p <= 0.05) == pytest.approx(0.05, abs=0.02)
    assert np.mean(p <= 0.10) == pytest.approx(0.10, abs=0.025)


def _rotated_readings(rng, n, B):
    """B null recordings of n readings (3 axes) whose noise, besides a white part, is a small
    rotation per reading (a re-seating): scatter across the reference, none along it. The
    references cycle through six directions. Whitened by a unit σ, as a noise model that does
    not know the rotation would."""
    ref = np.tile(np.eye(3)[[0, 1, 2, 0, 1, 2]] * np.array([1, 1, 1, -1, -1, -1])[:, None],
                  (n // 6 + 1, 1))[:n]
    white = rng.standard_normal((n, 3, B)) * 0.6
    rot = np.cross(rng.standard_normal((n, B, 3)) * 1.6, ref[:, None, :]).transpose(0, 2, 1)
    return ref, (white + rot).reshape(3 * n, B)


def _turn_columns(ref):
    """Per direction class, a field across the reference (what a pose turn fits)."""
    n = ref.shape[0]
    cls = np.argmax(np.abs(ref), axis=1) + 3 * (ref.sum(1) < 0)
    cols = []
    for c in range(6):
        for a in range(3):
            x = np.zeros((n, 3))
            on = cls == c
            if np.any(np.abs(ref[on, a]) > 0.5):
                continue  # along the reference: not a turn
            x[on, a] = 1.0
            cols.append(x.ravel())
    return np.column_stack(cols)


def test_sign_flip_null_holds_the_level_of_a_turn_under_reseating_noise():
    """A re-seating error (a rotation per visit) makes the across-reference scatter larger
    than the white noise model says. The F test of fields across the reference against
    Gaussian replicates then runs far above its level; against sign flips of the
    recording's own residual, one per reading (stats.wild_replicates), at it."""
    rng = np.random.default_rng(21)
    n, B, R = 120, 200, 300
    ref, Y = _rotated_readings(rng, n, R)
    row = np.repeat(np.arange(n), 3)
    X0 = np.kron(np.ones((n, 1)), np.eye(3))  # a bias per axis: the "base model"
    U = stats.orthonormal_basis(X0)
    Xt = _turn_columns(ref)
    p_gauss, p_wild = [], []
    for r in range(R):
        e = stats.project_out(U, Y[:, r])
        lp, _, _, _, _ = stats.linear_stats(U, Xt, e, np.zeros((3 * n, 1)))
        G = stats.project_out_inplace(U, rng.standard_normal((3 * n, B)))
        W = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, B)))
        for E, out in ((G, p_gauss), (W, p_wild)):
            lpn = stats.linear_stats(U, Xt, e, E)[1]
            out.append((1 + np.sum(lpn <= lp)) / (B + 1))
    p_gauss, p_wild = np.array(p_gauss), np.array(p_wild)
    assert np.mean(p_gauss <= 0.05) > 0.1  # measured 0.15: three times the level
    assert np.mean(p_wild <= 0.05) == pytest.approx(0.05, abs=0.03)
    assert np.mean(p_wild <= 0.20) == pytest.approx(0.20, abs=0.06)


def test_sign_flips_keep_each_readings_residual_up_to_its_sign():
    rng = np.random.default_rng(3)
    n = 40
    row = np.repeat(np.arange(n), 3)
    U = np.zeros((3 * n, 0))
    e = rng.choice([-1.0, 1.0], 3 * n) * rng.uniform(0.5, 1.5, 3 * n)  # none beyond the cap
    W = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, 50)))
    ratio = (W / e[:, None]).reshape(n, 3, 50)
    assert np.allclose(np.abs(ratio), 1.0)
    assert np.allclose(ratio, ratio[:, :1, :])  # one sign per reading, all three axes
    assert 0.3 < np.mean(ratio > 0) < 0.7


def test_a_reading_far_out_is_capped_in_the_sign_flips_with_its_direction():
    """A reading carrying a strong localised effect counts in the replicates as the largest
    Gaussian reading would (stats.reading_cap), in its own direction; the others unchanged."""
    rng = np.random.default_rng(4)
    n = 200
    row = np.repeat(np.arange(n), 3)
    e = rng.standard_normal(3 * n)
    e[30:33] = [40.0, -30.0, 0.0]
    cap = stats.reading_cap(e, row)
    assert cap[10] < 0.2 and np.sum(cap < 1.0) <= 3
    W = stats.wild_replicates(rng, e, np.zeros((3 * n, 0)), row, np.empty((3 * n, 20)))
    v = W[30:33, 0]
    assert np.allclose(np.abs(v / np.linalg.norm(v)), [0.8, 0.6, 0.0])
    size2 = np.sum(v**2) / stats.robust_scale(e[:, None], 1.0)[0] ** 2
    assert size2 == pytest.approx(sps.chi2.isf(1 / (2 * n), 3), rel=1e-6)


def _outlier_p_as_diagnosed(rng, e, row, n, g, B):
    """The outlier test's bootstrap p of one recording's residual ``e`` (U empty), its null's
    ν read from the recording as ``diagnose._reading_dof`` reads it (stats.NULL_TAIL_Z)."""
    U = np.zeros((n * g, 0))
    s = float(stats.robust_scale(e[:, None], 1.0)[0])
    pb = SimpleNamespace(m=n * g, row=row, ctx=SimpleNamespace(n=n), shared_t_loading=None)
    nu, _ = importlib.import_module("calibration.discrepancy.diagnose")._reading_dof(
        pb, U, e, s, [])
    t, _, _ = stats.row_stats(U, e, np.zeros((n * g, 1)), row, n, s, np.ones(1), set())
    E = rng.standard_normal((n * g, B))
    _, null_max, _ = stats.row_stats(U, e, E, row, n, s, stats.robust_scale(E, 1.0), set(),
                                     None, nu, rng)
    return (1 + np.sum(null_max >= t.max())) / (B + 1)


def test_outlier_null_holds_a_tail_too_mild_to_show_at_two_standard_errors():
    """Readings whose three axes share a Student-t scale with ν = 40 (the tail of the second
    generator's null capture means, issue 22), 150 per recording: 100–300 readings cannot
    show such a tail at 2 standard errors of the quantile ratio, and against the Gaussian
    null their max was at its 5 % level in 15 % of 400 recordings (the verdict's excess of
    `outlier` false alarms). With ν read at its point estimate (stats.NULL_TAIL_Z) it is at
    most twice the nominal rate; on Gaussian readings it stays at or below nominal."""
    n, g, B, nu_true = 150, 3, 200, 40.0
    row = np.repeat(np.arange(n), g)
    rng = np.random.default_rng(21)
    mild = []
    for _ in range(400):
        w = np.sqrt(nu_true / rng.chisquare(nu_true, n))
        mild.append(_outlier_p_as_diagnosed(rng, rng.standard_normal(n * g) * w[row], row, n,
                                            g, B))
    gauss = [_outlier_p_as_diagnosed(rng, rng.standard_normal(n * g), row, n, g, B)
             for _ in range(200)]
    assert np.mean(np.array(mild) <= 0.05) <= 2 * 0.05
    # binomial sd at 200 recordings: 1.5 % at 5 %
    assert np.mean(np.array(gauss) <= 0.05) <= 0.05 + 2 * 0.015
