"""The noise a recording itself shows (issue 22): vibration that is not rectified, placement.

Recordings come from the second blind generator (benchmarks/blind/gen2) with synthetic
noise pools (the benchmark draws them from the shared real recordings; a test must not
name a path outside the repository): white sensor noise and a slow bench vibration, an
AR(1) process that barely averages down within a 0.5 s capture.
"""

import numpy as np
import pytest
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose, problem, stats
from calibration.discrepancy.context import base_context
from calibration.recording import Recording


def _pools(phi: float = 0.9) -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - phi**2)], [1.0, -phi], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def _null_with_vibration(seed: int) -> Recording:
    """A one-way staircase on 18 positions, 50 samples per capture, 1 mg of slow vibration
    (zero mean: not rectified) on the plateaus below 5 °C, no effect."""
    rng = np.random.default_rng(200 + seed)
    pr = protocol.draw_protocol(rng, kind="oneway", schedule="sparse18", columns=("sensor_c",),
                                soak_min=20.0)
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 50, "sensor_noise_g": 60e-6,
                               "vib_sd_g": tuple(1e-3 if t < 5 else 0.0
                                                 for t in pr.setpoints_c)})
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(pr.setpoints_c), 10)
    return Recording.from_columns(sim.record(pr, sensor, _pools(), None, 0.0, pat, seed))


# Seeds whose recording sd/√n whitening called an outlier (5 of seeds 0–7 were flagged that
# way, 0 of 8 with the recording's own scatter).
@pytest.mark.parametrize("seed", [1, 5])
def test_a_null_with_slow_unrectified_vibration_is_not_an_outlier(seed, monkeypatch):
    rec = _null_with_vibration(seed)
    d = diagnose(rec, seed=0, n_null=100)
    assert d.findings == [] and d.mismatch is False
    assert d.noise_source.startswith("sd/sqrt(n) scaled to the scatter within plateaus")
    # The same recording whitened by sd/√n alone, its null Gaussian per reading: its
    # vibrating plateaus' readings were named outliers (the test can fail). (The null matched
    # to the readings' own tails alone catches this mis-weighting too: both are switched off.)
    monkeypatch.setattr(problem, "SCATTER_FROM_RESIDUAL", False)
    monkeypatch.setattr(stats, "NULL_TAIL_Z", np.inf)
    assert "outlier" in [f.effect for f in diagnose(rec, seed=0, n_null=100).findings]


def test_capture_noise_gives_the_vibration_its_own_averaging_factor():
    """Floor rows average 0.45 × white (a sensor's own noise), vibrating rows 20 × white
    on their excess: both are recovered, where one κ would misstate each by ~3×."""
    rng = np.random.default_rng(1)
    floor = np.full((300, 3), 10e-6**2)
    sig2 = floor.copy()
    sig2[:100] += 100e-6**2  # vibrating rows: sd²/n well above the floor
    true_var = 0.45 * floor + 20.0 * (sig2 - floor)
    e = rng.standard_normal((300, 3)) * np.sqrt(true_var)
    sig, kappa, tau = problem.capture_noise(e, np.sqrt(sig2), 1.0, None, floor)
    ratio = sig**2 / true_var
    assert kappa == pytest.approx(21.0, rel=0.25)
    assert np.median(ratio[:100]) == pytest.approx(1.0, rel=0.25)
    assert np.median(ratio[100:]) == pytest.approx(1.0, rel=0.25)


def test_a_quiet_plateau_without_a_residual_of_its_own_keeps_a_third_of_its_sd():
    """The quietest plateau sets the floor but has no within-plateau residual (too few
    readings); the others scatter above it. Its κ₀ is then unconstrained: it must not
    claim a capture mean 30× more precise than its samples' sd/√n (the second generator's
    null 0224: 0.4 µg against 9 µg, and a χ² excess of 9 on a null)."""
    rng = np.random.default_rng(4)
    sig2 = np.full((120, 3), 10e-6**2)
    sig2[20:] = 11e-6**2  # the informed plateaus, a little above the floor
    floor = np.full((120, 3), 10e-6**2)
    # Their residuals scatter as much as their sd²/n exceeds the floor: κ on that excess
    # alone explains them, and nothing ties κ₀ down.
    e = rng.standard_normal((120, 3)) * np.sqrt(sig2 - floor)
    e[:20] = np.nan  # the floor's plateau: no residual of its own
    sig, kappa, tau = problem.capture_noise(e, np.sqrt(sig2), 1.0, None, floor)
    assert np.all(sig[:20] >= np.sqrt(problem.KAPPA0_MIN) * 10e-6 * (1 - 1e-9))
    assert np.all(sig[:20] > 0.3 * 10e-6)


def test_within_plateau_residual_keeps_noise_and_drops_plateau_changes():
    """Bias jumps, a scale change and a settling trend per plateau leave only the noise."""
    rng = np.random.default_rng(3)
    n_step, n_pos = 6, 24
    steps = np.repeat(np.arange(n_step), n_pos)
    ref = rng.standard_normal((steps.size, 3))
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    t_s = np.arange(steps.size) * 30.0 + steps * 3600.0
    temp = -40.0 + 20.0 * steps + 0.1 * rng.standard_normal(steps.size)
    raw = ref * (1.0 + 1e-3 * steps[:, None]) + 5e-4 * steps[:, None]
    raw += 2e-4 * np.exp(-(t_s - steps * 3600.0) / 600.0)[:, None]  # settling in a plateau
    noise = 10e-6 * rng.standard_normal(raw.shape)
    cols = {"t_s": t_s, "step": steps, "chamber_c": temp, "ref_x": ref[:, 0],
            "ref_y": ref[:, 1], "ref_z": ref[:, 2], "ax": raw[:, 0] + noise[:, 0],
            "ay": raw[:, 1] + noise[:, 1], "az": raw[:, 2] + noise[:, 2]}
    rec = Recording.from_columns(cols)
    ctx = base_context(rec, "reference", rec.ref_g)
    e = problem.within_step_residual(rec.raw_g, rec.ref_g, ctx)
    assert float(np.sqrt(np.mean(e**2))) == pytest.approx(10e-6, rel=0.3)


def test_the_temperature_term_is_not_counted_twice():
    """Residuals that are exactly sd²/n plus a known temperature-channel variance: the fit
    leaves κ ≈ 1 and τ ≈ 0, and σ² is their sum once (fitted before the term, τ took it
    in and the term was added again on top)."""
    rng = np.random.default_rng(5)
    sig2 = np.full((400, 3), 10e-6**2)
    known = np.zeros((400, 3))
    known[:200] = 30e-6**2  # the cold half: a large tempco on a noisy channel
    e = rng.standard_normal((400, 3)) * np.sqrt(sig2 + known)
    sig, kappa, tau = problem.capture_noise(e, np.sqrt(sig2), 1.0, known)
    assert kappa == pytest.approx(1.0, abs=0.2) and tau < 4e-6
    assert np.median(sig[:200] ** 2 / (sig2 + known)[:200]) == pytest.approx(1.0, rel=0.2)


def _plateau_inflation_at_a_far_reading(seed: int) -> tuple[float, bool]:
    """Six plateaus of 18 readings (the sparse schedule), white noise σ = 10 µg, one reading
    12 σ off on the third plateau: (step_inflation's factor on that plateau against the
    true σ, whether the far reading's within-plateau residual is left out)."""
    rng = np.random.default_rng(seed)
    n_step, n_pos, sd = 6, 18, 10e-6
    steps = np.repeat(np.arange(n_step), n_pos)
    ref = rng.standard_normal((steps.size, 3))
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    t_s = np.arange(steps.size) * 30.0 + steps * 3600.0
    temp = -40.0 + 20.0 * steps + 0.1 * rng.standard_normal(steps.size)
    raw = (ref * (1.0 + 1e-3 * steps[:, None]) + 5e-4 * steps[:, None]
           + sd * rng.standard_normal(ref.shape))
    far = 2 * n_pos + 7
    raw[far] += 12.0 * sd / np.sqrt(3.0)
    cols = {"t_s": t_s, "step": steps, "chamber_c": temp, "ref_x": ref[:, 0],
            "ref_y": ref[:, 1], "ref_z": ref[:, 2], "ax": raw[:, 0], "ay": raw[:, 1],
            "az": raw[:, 2]}
    rec = Recording.from_columns(cols)
    ctx = base_context(rec, "reference", rec.ref_g)
    e = problem.within_step_residual(rec.raw_g, rec.ref_g, ctx)
    f = problem.step_inflation(e, np.full(e.shape, sd), steps)
    return float(f[far]), bool(np.isnan(e[far]).all())


def test_a_reading_far_off_does_not_set_its_plateaus_noise(monkeypatch):
    """The plateau's own fit (9 columns on 18 readings) spread a reading 12 σ off into its
    neighbours' residuals and inflated the plateau's σ (median factor 1.6 over ten
    recordings); refitted without it, the plateau keeps the noise's σ (issue 22: the
    outlier test's tail estimate read that spread as a heavier tail and lost outliers)."""
    robust = [_plateau_inflation_at_a_far_reading(s) for s in range(10)]
    assert all(left_out for _, left_out in robust)
    assert np.median([f for f, _ in robust]) <= 1.05
    monkeypatch.setattr(problem, "ROBUST_PLATEAU_FIT", False)
    plain = [_plateau_inflation_at_a_far_reading(s)[0] for s in range(10)]
    assert np.median(plain) >= 1.3
