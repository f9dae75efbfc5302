"""The lead's SFEM fits (calibration/fit.py) and the batch path, on simulated data."""

import numpy as np
import pytest

from benchmarks.batch_fit import fit_reference_batch
from calibration import fit, schedules, sfem
from calibration.errors import NotIdentifiable
from simulators.campaign_sim import simulate_static_run
from simulators.truth import SensorTruth


def _static(seed: int, sched: np.ndarray, n_samples: int = 200):
    truth = SensorTruth.adxl355_typical(seed)
    sim = simulate_static_run(truth, sched, 25.0, samples_per_position=n_samples, seed=seed)
    return truth.params_at(25.0).to_vector(), sim.recording


@pytest.mark.parametrize("seed", range(4))
def test_reference_fit_recovers_all_twelve_within_stated_uncertainty(seed: int) -> None:
    true, rec = _static(seed, schedules.table1())
    res = fit.fit_reference(rec.raw_g, rec.ref_g, rec.sigma_g)
    assert res.success and res.identifiable.all()
    z = (res.params.to_vector() - true) / res.stderr
    # 12 parameters × 4 seeds: |z| < 4.5 has a per-test false-alarm rate ~1e-4.
    assert np.all(np.abs(z) < 4.5), dict(zip(sfem.PARAM_NAMES, np.round(z, 2), strict=True))
    # The stated uncertainty is of the right size (not inflated to hide a bias).
    assert np.all(res.stderr < 20e-6), res.stderr
    assert 0.3 < res.chi2_red < 3.0


def test_reference_fit_uncertainty_is_calibrated_over_many_runs() -> None:
    zs = []
    for seed in range(12):
        true, rec = _static(100 + seed, schedules.table1())
        res = fit.fit_reference(rec.raw_g, rec.ref_g, rec.sigma_g)
        zs.append((res.params.to_vector() - true) / res.stderr)
    z = np.concatenate(zs)
    assert 0.7 < np.std(z) < 1.35, np.std(z)  # a wrong covariance shows up here
    assert abs(np.mean(z)) < 0.3


def test_reference_fit_removes_the_errors() -> None:
    _, rec = _static(5, schedules.table1())
    res = fit.fit_reference(rec.raw_g, rec.ref_g, rec.sigma_g)
    assert res.rmse_norm_before_ug > 1000.0  # ~1 % scale, ~25 mg offsets uncalibrated
    assert res.rmse_norm_ug < 20.0
    assert res.rmse_vector_ug is not None and res.rmse_vector_ug < 20.0


def test_norm_mode_recovers_b_s_c_and_says_m_is_not_identifiable() -> None:
    true, rec = _static(7, schedules.sphere(36))
    res = fit.fit_norm(rec.raw_g, rec.sigma_g)
    assert res.mode == "norm"
    assert list(res.identifiable) == [True] * 9 + [False] * 3
    assert np.all(np.isnan(res.covariance[9:, :])) and np.all(np.isnan(res.covariance[:, 9:]))
    for name in ("mx", "my", "mz"):
        assert "rotation" in res.not_identifiable_why[name]
    # A = M·C·S and |A v| = |C S v|: the norm sees exactly C and S (and b).
    z = (res.params.to_vector()[:9] - true[:9]) / res.stderr[:9]
    assert np.all(np.abs(z) < 4.5), np.round(z, 2)
    assert res.rmse_norm_ug < 20.0


def test_six_position_norm_mode_is_rank_deficient() -> None:
    _, rec = _static(2, schedules.six_position())
    with pytest.raises(NotIdentifiable, match="needs more than 6 residuals, got 6 from 6"):
        fit.fit_norm(rec.raw_g, rec.sigma_g)
    ident = schedules.identifiability(schedules.six_position(), "norm")
    assert ident.rank < 9
    assert {"ayx", "azx", "azy"} <= set(ident.undetermined)


def test_six_positions_twice_is_still_rank_deficient_in_norm_mode() -> None:
    # Enough rows to pass the count check, but the same 6 directions: the
    # non-orthogonality enters |g| only at second order there. The fit must say
    # so, hold α at nominal, and still recover b and S within their uncertainty.
    true, rec = _static(3, np.vstack([schedules.six_position()] * 2))
    res = fit.fit_norm(rec.raw_g, rec.sigma_g)
    assert not res.identifiable[sfem.ALPHA].any()
    assert np.all(np.isnan(res.stderr[sfem.ALPHA]))
    assert all("do not constrain" in res.not_identifiable_why[n] for n in ("ayx", "azx", "azy"))
    np.testing.assert_array_equal(res.params.to_vector()[sfem.ALPHA], 0.0)
    b_s = slice(0, 6)
    assert res.identifiable[b_s].all()
    # b and S absorb α only at second order (α² ~ 1e-6): within stated σ plus that.
    err = np.abs(res.params.to_vector()[b_s] - true[b_s])
    assert np.all(err < 5 * res.stderr[b_s] + 1e-5), (err, res.stderr[b_s])


@pytest.mark.parametrize(
    ("raw", "ref", "match"),
    [
        (np.zeros((24, 2)), np.zeros((24, 3)), "shape"),
        (np.zeros((24, 3)), np.zeros((23, 3)), "differ"),
        (np.zeros(72), np.zeros((24, 3)), "shape"),
        (np.full((24, 3), np.nan), np.zeros((24, 3)), "non-finite"),
    ],
)
def test_bad_shapes_raise(raw: np.ndarray, ref: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        fit.fit_reference(raw, ref)


def test_norm_bad_shape_and_too_few_positions_raise() -> None:
    with pytest.raises(ValueError, match="shape"):
        fit.fit_norm(np.zeros((20, 4)))
    with pytest.raises(NotIdentifiable):
        fit.fit_reference(np.eye(3), np.eye(3))


def _batch_problems(k: int, sched: np.ndarray) -> tuple[np.ndarray, ...]:
    recs = [_static(40 + i, sched)[1] for i in range(k)]
    return (np.stack([r.raw_g for r in recs]), np.stack([r.ref_g for r in recs]),
            np.stack([r.sigma_g for r in recs]))


@pytest.mark.parametrize("weighted", [False, True])
def test_batch_fit_equals_the_single_fits(weighted: bool) -> None:
    raw, ref, sig = _batch_problems(6, schedules.table1())
    batch = fit_reference_batch(raw, ref, sig if weighted else None)
    for k in range(raw.shape[0]):
        one = fit.fit_reference(raw[k], ref[k], sig[k] if weighted else None)
        np.testing.assert_allclose(batch.params[k], one.params.to_vector(), atol=1e-12)
        np.testing.assert_allclose(batch.stderr[k], one.stderr, rtol=1e-6)
        assert batch.rmse_norm_ug[k] == pytest.approx(one.rmse_norm_ug, abs=1e-6)
        assert batch.rmse_vector_ug[k] == pytest.approx(one.rmse_vector_ug, abs=1e-6)
        assert batch.chi2_red[k] == pytest.approx(one.chi2_red, rel=1e-6)
    assert batch.identifiable.all()


def test_batch_fit_of_problems_with_large_errors_still_matches() -> None:
    # Errors far larger than a MEMS part has (10 % scale, 0.1 rad): still one optimum.
    rng = np.random.default_rng(0)
    ref = np.broadcast_to(schedules.cube14(), (3, 14, 3)).copy()
    raw = np.empty_like(ref)
    for k in range(3):
        p = sfem.identity_vector() + rng.normal(0, 0.1, 12)
        raw[k] = sfem.SfemParams.from_vector(p).invert(ref[k]) + rng.normal(0, 1e-4, (14, 3))
    batch = fit_reference_batch(raw, ref)
    for k in range(3):
        one = fit.fit_reference(raw[k], ref[k])
        np.testing.assert_allclose(batch.params[k], one.params.to_vector(), atol=1e-10)


def test_batch_fit_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match="shape"):
        fit_reference_batch(np.zeros((24, 3)), np.zeros((24, 3)))
    with pytest.raises(ValueError, match="differ"):
        fit_reference_batch(np.zeros((2, 24, 3)), np.zeros((2, 23, 3)))
    with pytest.raises(NotIdentifiable):
        fit_reference_batch(np.zeros((2, 3, 3)), np.zeros((2, 3, 3)))
