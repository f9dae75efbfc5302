"""Metrics: Eq. 9, Eq. 10 tilt, Table 5 SEOQ, thermal drift."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import metrics


def test_rmse_norm_is_eq9_in_ug() -> None:
    g = np.array([[0, 0, 1.001], [0, 0.999, 0]])
    assert metrics.rmse_norm_ug(g) == pytest.approx(1000.0)


def test_vector_error_per_axis() -> None:
    ref = np.zeros((4, 3))
    cal = ref + np.array([1e-6, 2e-6, 0.0])
    per_axis, total = metrics.vector_error_ug(cal, ref)
    np.testing.assert_allclose(per_axis, [1.0, 2.0, 0.0])
    assert total == pytest.approx(np.sqrt(5 / 3))


def test_tilt_angles_of_eq10() -> None:
    # Pitch by 30° about x: gravity in the sensor frame gets a −Y component.
    a = np.radians(30.0)
    pitch, roll = metrics.tilt_angles_deg(np.array([[0.0, -np.sin(a), -np.cos(a)]]))
    assert pitch[0] == pytest.approx(30.0) and roll[0] == pytest.approx(0.0)
    pitch, roll = metrics.tilt_angles_deg(np.array([[np.sin(a), 0.0, -np.cos(a)]]))
    assert roll[0] == pytest.approx(30.0) and pitch[0] == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("before", "after", "seoq"),
    [  # the seed's Table 5: (φ; θ) without and after calibration, SEOQ in %
        ((-0.77, 0.59), (-0.70, -0.30), (0.2, 3.0)),
        ((14.18, -0.62), (14.61, -0.15), (1.4, 1.6)),
        ((29.18, -0.63), (30.13, 0.01), (3.2, 2.1)),
        ((-0.96, -15.83), (-0.91, -15.72), (0.2, 0.4)),
        ((14.31, -15.98), (14.76, -15.82), (1.5, 0.5)),
        ((29.00, -29.62), (29.98, -29.76), (3.3, 0.5)),
    ],
)
def test_seoq_reproduces_table5(before: tuple, after: tuple, seoq: tuple) -> None:
    got = metrics.seoq_percent(np.array(before), np.array(after))
    np.testing.assert_allclose(got, seoq, atol=0.051)


def test_tilt_table_rows() -> None:
    ref = np.array([[0.0, 0.0, -1.0]])
    rows = metrics.tilt_table(ref + [0.01, 0.0, 0.0], ref, ref)
    assert rows[0]["err_cal_deg"] == pytest.approx(0.0)
    assert rows[0]["err_raw_deg"] == pytest.approx(np.degrees(np.arctan(0.01)), rel=1e-6)


def test_thermal_drift_slope_and_range_with_orientation_groups() -> None:
    rng = np.random.default_rng(0)
    T = np.repeat(np.arange(-40.0, 61.0, 10.0), 3)
    groups = np.tile(np.arange(3), 11)
    base = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]])[groups]
    slope = np.array([100e-6, -50e-6, 20e-6])  # g/K
    v = base + np.outer(T, slope) + rng.normal(0, 1e-7, (33, 3))
    d = metrics.thermal_drift(v, T, groups)
    np.testing.assert_allclose(d.slope_ug_per_k, [100, -50, 20], atol=0.1)
    np.testing.assert_allclose(d.drift_mg, [10.0, -5.0, 2.0], atol=0.01)
    assert d.range_c == (-40.0, 60.0)
    both = metrics.drift_before_after(v, base, T, groups)
    assert abs(both["after"]["slope_ug_per_k"][0]) < 0.01


def test_thermal_drift_group_means_match_per_group_masks() -> None:
    """The bincount group means give the slope the per-group masks gave (many groups)."""
    rng = np.random.default_rng(3)
    n = 3000
    T = rng.uniform(-40.0, 60.0, n)
    groups = rng.integers(0, 1200, n) * 7 - 50  # sparse, negative ids: not 0..k-1
    v = rng.normal(0.0, 1.0, (n, 3))
    y = np.column_stack([v, np.linalg.norm(v, axis=1) - 1.0])
    Tc = T.copy()
    for gid in np.unique(groups):  # the naive form: one mask per group
        m = groups == gid
        y[m] -= y[m].mean(axis=0)
        Tc[m] -= Tc[m].mean()
    naive = (Tc @ y) / float(Tc @ Tc) * 1e6
    d = metrics.thermal_drift(v, T, groups)
    np.testing.assert_allclose(d.slope_ug_per_k, naive[:3], rtol=1e-12)
    assert d.norm_slope_ug_per_k == pytest.approx(naive[3], rel=1e-12)


def test_minus_group_means_matches_per_group_masks_for_vectors_and_tables() -> None:
    """The drift report's and drift figure's centring: one pass equals a mask per group."""
    rng = np.random.default_rng(5)
    groups = rng.integers(0, 40, 500)
    v = rng.normal(0.0, 1.0, (500, 3))
    naive = v.copy()
    for gid in np.unique(groups):
        m = groups == gid
        naive[m] -= naive[m].mean(axis=0)
    np.testing.assert_allclose(metrics.minus_group_means(groups, v), naive, atol=1e-14)
    np.testing.assert_allclose(metrics.minus_group_means(groups, v[:, 1]), naive[:, 1], atol=1e-14)
