"""Norm mode: σ includes the temperature channel's noise, as in reference mode (issue 10)."""

from __future__ import annotations

from dataclasses import replace

from calibration.discrepancy import diagnose
from calibration.recording import Recording
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]


def test_norm_mode_nulls_with_a_noisy_temperature_channel_are_consistent():
    """A 0.1 °C chamber PV: before the fix 11 of 12 such nulls were flagged."""
    flagged = []
    for seed in range(3):
        truth = SensorTruth.adxl355_typical(seed=seed)
        rec = simulate_campaign(truth, ONE_WAY, seed=seed + 100, soak_min=20,
                                physics=replace(RigPhysics(), pv_noise_c=0.1, die_tau_s=30.0),
                                temperature_columns=("chamber_c",))
        rec = Recording.from_columns({k: v for k, v in rec.columns.items()
                                      if not k.startswith("ref_")})
        d = diagnose(rec, n_null=50, seed=seed)
        assert d.mode == "norm"
        flagged.append(d.mismatch)
    assert flagged == [False, False, False]
