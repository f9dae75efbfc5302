"""Model-error floor on the weights and hand-placed references (calibration/fit.py)."""

import numpy as np
import pytest

from calibration import fit, schedules, sfem
from simulators.truth import SensorTruth


def _truth() -> sfem.SfemParams:
    return SensorTruth.adxl355_typical(3).params_at(25.0)


def _readings(truth: sfem.SfemParams, ref: np.ndarray, sem_g: np.ndarray, extra_g: float,
              rng: np.random.Generator) -> np.ndarray:
    """Interval means: noise sd/√n per interval plus ``extra_g`` of model error."""
    noise = rng.normal(0.0, 1.0, ref.shape) * sem_g[:, None]
    return truth.invert(ref) + noise + rng.normal(0.0, extra_g, ref.shape)


def test_no_floor_when_residuals_are_noise() -> None:
    rng = np.random.default_rng(1)
    ref = schedules.sphere(36)
    sem = np.full(36, 20e-6)
    raw = _readings(_truth(), ref, sem, 0.0, rng)
    sig = np.broadcast_to(sem[:, None], ref.shape)
    auto = fit.fit_norm(raw, sig)
    plain = fit.fit_norm(raw, sig, model_floor=None)
    assert auto.model_floor_g == 0.0
    np.testing.assert_array_equal(auto.params.to_vector(), plain.params.to_vector())


def test_floor_found_from_residual_excess_and_long_interval_no_longer_dominates() -> None:
    # 36 intervals, one of them 25× longer (σ 5× smaller), all with 300 µg of model
    # error the averaging cannot remove: the floor should come out near 300 µg.
    rng = np.random.default_rng(2)
    ref = schedules.sphere(36)
    sem = np.full(36, 50e-6)
    sem[0] = 10e-6
    raw = _readings(_truth(), ref, sem, 300e-6, rng)
    sig = np.broadcast_to(sem[:, None], ref.shape)
    res = fit.fit_norm(raw, sig)
    assert 150e-6 < res.model_floor_g < 500e-6, res.model_floor_g
    # With the floor, the long interval's weight is within 10 % of the others'.
    w = 1.0 / (sem**2 + res.model_floor_g**2)
    assert w[0] / w[1] < 1.1
    # The floor makes the reduced χ² consistent with one (that is its definition).
    assert 0.5 < res.chi2_red < 1.5
    fixed = fit.fit_norm(raw, sig, model_floor=res.model_floor_g)
    np.testing.assert_allclose(fixed.params.to_vector(), res.params.to_vector(), atol=1e-12)


def test_model_floor_estimator_solves_its_equation() -> None:
    rng = np.random.default_rng(3)
    s = rng.uniform(1e-5, 5e-5, 200)
    r = rng.normal(0.0, 1.0, 200) * np.sqrt(s**2 + (2e-4) ** 2)
    tau = fit.model_floor_g(r, s, 9)
    assert np.sum(r**2 / (s**2 + tau**2)) == pytest.approx(200 - 9, rel=1e-8)
    assert 1.6e-4 < tau < 2.4e-4
    assert fit.model_floor_g(r[:9], s[:9], 9) == 0.0  # no spare degree of freedom


def test_bad_model_floor_is_refused() -> None:
    ref = schedules.sphere(20)
    with pytest.raises(ValueError, match="model_floor"):
        fit.fit_norm(ref, np.full((20, 3), 1e-5), model_floor="median")
    with pytest.raises(ValueError, match="model_floor"):
        fit.fit_norm(ref, np.full((20, 3), 1e-5), model_floor=-1.0)


def _tilted(ref: np.ndarray, tilt_rad: float, rng: np.random.Generator) -> np.ndarray:
    """Each direction rotated by a random small rotation of ~``tilt_rad``."""
    out = np.empty_like(ref)
    for i, v in enumerate(ref):
        out[i] = sfem.rotation(rng.normal(0.0, tilt_rad, 3)) @ v
    return out


@pytest.mark.parametrize("seed", range(3))
def test_hand_placed_six_faces_keep_g_exact_where_an_exact_reference_fit_cannot(
        seed: int) -> None:
    # Six faces placed by hand, each ~1° off its label; the sensor's |g| error is then
    # judged at 30 other orientations it never saw.
    rng = np.random.default_rng(10 + seed)
    truth = _truth()
    labels = schedules.six_position()
    placed = _tilted(labels, np.radians(1.0), rng)
    sem = np.full((6, 3), 5e-6)
    raw = truth.invert(placed) + rng.normal(0.0, 5e-6, (6, 3))
    other_true = schedules.sphere(30)
    other_raw = truth.invert(other_true)

    def g_err_ug(res: fit.FitResult, x: np.ndarray) -> float:
        return float(np.sqrt(np.mean((np.linalg.norm(res.params.apply(x), axis=1) - 1) ** 2))
                     * 1e6)

    exact = fit.fit_reference(raw, labels, sem)
    hand = fit.fit_reference(raw, labels, sem, ref_tol_rad=np.radians(2.0))
    assert hand.ref_tol_rad is not None and exact.ref_tol_rad is None
    # On the six: |g| exact to within noise; the exact-label fit leaves the tilt there.
    assert g_err_ug(hand, raw) < 20.0
    assert g_err_ug(exact, raw) > 3 * g_err_ug(hand, raw)
    # At orientations it never saw, the tilt that the exact-label fit turned into
    # bias and scale costs more |g| error than the hand-placed fit leaves.
    assert g_err_ug(hand, other_raw) < g_err_ug(exact, other_raw)
    # The stated uncertainty of the non-orthogonality reflects the placement (2°), not σ.
    assert np.all(hand.stderr[sfem.ALPHA] > 1e-3)


def test_hand_placed_tolerance_is_validated() -> None:
    labels = schedules.six_position()
    with pytest.raises(ValueError, match="ref_tol_rad"):
        fit.fit_reference(labels, labels, ref_tol_rad=0.0)
    with pytest.raises(ValueError, match="ref_tol_rad"):
        fit.fit_reference(labels, labels, ref_tol_rad=np.array([0.1] * 5 + [np.nan]))


def test_campaign_steps_find_a_floor_only_when_the_model_leaves_structure() -> None:
    import thermal_sim

    from calibration.thermal import fit_campaign

    _, rec = thermal_sim.campaign(seed=5)
    clean = fit_campaign(rec)
    assert all(st.fit.model_floor_g == 0.0 for st in clean.steps)
    # A fixed 500 µg error per position (what a mounting defect would leave) that
    # averaging cannot remove: every step must see it and widen its weights.
    rng = np.random.default_rng(0)
    pos = rec.positions()
    bump = rng.normal(0.0, 500e-6, (pos.max() + 1, 3))[pos]
    for j, c in enumerate(("ax", "ay", "az")):
        rec.columns[c] = rec.columns[c] + bump[:, j]
    dirty = fit_campaign(rec)
    assert all(st.fit.model_floor_g > 100e-6 for st in dirty.steps)
    assert dirty.model.method == "joint"
