"""The statistics behind the blind-benchmark fixes (docs/diagnosis.md, docs/blind-benchmark.md)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import stats as sps

from benchmarks.blind import detectability
from calibration.discrepancy import diagnose, stats
from calibration.discrepancy.diagnose import heldout_improved
from calibration.discrepancy.problem import build_problem
from calibration.recording import Recording
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]


def test_long_lag_on_a_short_soak_is_one_lag_finding():
    """τ ≫ soak: the die never settles (ΔT ≈ 6–18 °C). The lag term must carry it alone."""
    truth = SensorTruth.adxl355_typical(seed=31)
    ph = replace(RigPhysics(), die_tau_s=1600.0)
    rec = simulate_campaign(truth, ONE_WAY, soak_min=20.0, seed=32, physics=ph,
                            temperature_columns=("chamber_c",))
    d = diagnose(rec, n_null=30, seed=0)
    assert [f.effect for f in d.findings] == ["thermal_lag"]
    f = d.findings[0]
    assert f.parameters["tau_s"] == pytest.approx(1600.0, rel=0.05)
    assert f.heldout_rmse_after_ug < 1.2 * d.noise_ug < 0.1 * f.heldout_rmse_before_ug


def test_base_is_the_sfem_cubic_not_its_linear_surrogate():
    """Noise-free twin data (SFEM with cubic parameters): the base leaves nothing."""
    truth = SensorTruth.adxl355_typical(seed=33)
    sim = simulate_campaign(truth, ONE_WAY, seed=34, temperature_columns=("chamber_c",),
                            return_truth=True)
    cols = dict(sim.recording.columns)
    ideal = truth.ideal_raw_g(sim.recording.ref_g, sim.die_c)
    cols.update(ax=ideal[:, 0], ay=ideal[:, 1], az=ideal[:, 2], chamber_c=sim.die_c)
    pb = build_problem(Recording.from_columns(cols))
    Xw, yw = pb.X0 * pb.w[:, None], pb.y * pb.w
    r = yw - Xw @ np.linalg.lstsq(Xw, yw, rcond=None)[0]
    assert float(np.sqrt(np.mean(r**2))) < 0.01  # in noise units; the surrogate leaves ~0.1


def test_lag_test_is_one_sided_and_ranked_without_underflow():
    rng = np.random.default_rng(0)
    m = 600
    U = stats.orthonormal_basis(rng.standard_normal((m, 5)))
    x = stats.project_out(U, rng.standard_normal((m, 2)))
    E0 = stats.project_out(U, rng.standard_normal((m, 50)))
    noise = stats.project_out(U, rng.standard_normal(m))
    lp_pos = stats.linear_stats(U, x, noise + 0.5 * x[:, 0], E0, one_sided=True)[0]
    lp_neg = stats.linear_stats(U, x, noise - 0.5 * x[:, 0], E0, one_sided=True)[0]
    assert lp_pos < np.log(1e-6) and lp_neg == 0.0  # a die cannot lead the air
    # Far beyond double precision the log p still orders the evidence.
    assert np.isfinite(stats.f_logsf(1e7, 2, 700)) and stats.f_logsf(1e7, 2, 700) < \
        stats.f_logsf(1e6, 2, 700) < -1000
    assert stats.chi2_logsf(5000.0, 3) < stats.chi2_logsf(2000.0, 3) < -900


def test_heldout_gain_must_show_at_reported_resolution():
    assert heldout_improved(10.50, 10.40)
    assert not heldout_improved(10.4912, 10.4907)  # reported as 10.49 → 10.49
    assert not heldout_improved(10.40, 10.41)


def test_outlier_mds_pays_for_the_search_over_readings():
    """Two disturbed readings in N: the scan finds one of them with probability 1/2."""
    lam1 = np.array([0.2, 0.2])  # λ per disturbed reading at m = 1
    n_rows = 400
    m_star = detectability.minimum_detectable_rows(lam1, 3, n_rows)
    crit = detectability.threshold_rows(3, n_rows)
    miss = np.prod([sps.ncx2.cdf(crit, 3, (m_star * v) ** 2) for v in lam1])
    assert 1.0 - miss == pytest.approx(0.5, abs=1e-6)
    # Larger than the old criterion (one 1-dof test on both readings, no search) ...
    old = detectability.threshold(1) / float(np.sqrt(np.sum(lam1**2)))
    assert 1.7 < m_star / old < 2.2
    # ... and it grows with the number of readings to search.
    assert detectability.minimum_detectable_rows(lam1, 3, 4000) > m_star


def test_the_tail_probabilities_print_no_warning_at_zero(recwarn):
    # A statistic of 0 (nothing explained) is an ordinary value: its log p is 0, and the
    # asymptotic branch, unused there, must not put "divide by zero" on the user's terminal.
    assert stats.f_logsf(np.array([0.0, 1.0]), 3, 50)[0] == 0.0
    assert stats.chi2_logsf(np.array([0.0, 2.0]), 3)[0] == 0.0
    assert [str(w.message) for w in recwarn] == []
