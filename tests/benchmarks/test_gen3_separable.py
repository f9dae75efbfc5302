"""benchmarks/blind/gen3/separable (issue 22): the oracle of separability on a gen3 case —
the drawn effect's noise-free signature is what the effect put into the recording, the
recording less its noise-free output is noise of rms ≈ 1 in the diagnosis' units, and a
rival that is the effect's own column makes a "not established" answer honest."""

import dataclasses

import numpy as np

from benchmarks.blind.gen2.separable import Oracle, separability
from benchmarks.blind.gen2.separable import classify as oracle_class
from benchmarks.blind.gen3.case import draw_case, simulate
from benchmarks.blind.gen3.effects import draw_effect
from benchmarks.blind.gen3.noise import NoiseSpec
from benchmarks.blind.gen3.protocol import Protocol
from benchmarks.blind.gen3.schedules import faces
from benchmarks.blind.gen3.separable import (
    JUMP,
    ChannelOracle,
    named_rivals,
    noise_check,
    signature_g,
)
from benchmarks.blind.gen3.writer import write_csv
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.level import ALPHA


def _staircase(seed):
    """Five plateaus heated one way × 6 faces × 2 visits, white noise, a fine channel."""
    case = draw_case(seed)
    protocol = Protocol(setpoints_c=(-40.0, -10.0, 20.0, 50.0, 80.0), order="up",
                        schedule_name="faces", directions=faces(), visits=2, shuffled=True,
                        fixture="table", place_max_rad=0.0, move_s=20.0)
    noise = NoiseSpec(odr_hz=125.0, n=200, density_g=np.array([20e-6, 25e-6, 30e-6]),
                      nu=None, vibration=None, raw_lsb_g=None)
    thermal = dataclasses.replace(case.thermal, channel_lsb_c=0.01)
    return dataclasses.replace(case, protocol=protocol, noise=noise, thermal=thermal)


def test_a_power_cycle_on_a_one_way_staircase_is_honestly_not_established(tmp_path):
    drawn, info = draw_effect("session_offset", _staircase(5), 2.0)
    assert not info["absorbed"]
    rows, null = simulate(drawn.case, drawn), simulate(drawn.case)
    sig = signature_g(rows, drawn)
    means = np.array([[r["ax"], r["ay"], r["az"]] for r in rows])
    means0 = np.array([[r["ax"], r["ay"], r["az"]] for r in null])
    np.testing.assert_allclose(sig, means - means0, atol=1e-12)  # the same draws
    csv = tmp_path / "case.csv"
    write_csv(rows, csv)
    o = Oracle(csv)
    assert 0.7 < noise_check(o, rows) < 1.3
    # the report's entry for a power cycle on a one-way staircase names a jump at a T*
    doc = {"findings": [], "protocol": {"not_separable": [{
        "effects": ["session_offset"], "why": "…",
        "outside_catalogue": [f"{JUMP} a T* (outside the catalogue)"]}]}}
    rivals = named_rivals(doc, "session_offset", o, o.w(sig[:, :, None]))
    assert len(rivals) == 1 and rivals[0].startswith(JUMP)
    key = {"catalogue_id": "session_offset", "pattern": {"rows": []}}
    sep = separability(o, key, sig, rivals, ALPHA / 2)
    assert sep["base"]["power_cols"] > 0.5  # beyond the base model alone: detectable
    assert sep[rivals[0]]["lam_known"] < 1e-6  # the jump is the power cycle's own column
    assert oracle_class("not_established", sep, rivals) == "honest"
    assert oracle_class("not_established", sep, []) == "deficit"


def test_a_coarse_channels_rounding_is_noise_along_the_slope_in_the_channel_oracle(tmp_path):
    # one plateau's rounding error of the channel, u °C along ∂output/∂T: with a prior
    # variance pv per plateau, GLS leaves it λ = λ₀/(1 + pv·λ₀) ≤ 1/pv
    case = _staircase(5)
    rows = simulate(case)
    csv = tmp_path / "case.csv"
    write_csv(rows, csv)
    slope = np.array([case.sensor.output_g(np.array([r["ref_x"], r["ref_y"], r["ref_z"]]),
                                           r["die_c"] + 0.01)
                      - case.sensor.output_g(np.array([r["ref_x"], r["ref_y"], r["ref_z"]]),
                                             r["die_c"] - 0.01) for r in rows]) / 0.02
    steps = np.array([r["step"] for r in rows])
    sig = slope * 0.3 * (steps == 2)[:, None]  # 0.3 °C on plateau 2
    key = {"catalogue_id": "temperature_sensor", "pattern": {"rows": []}}
    plain = separability(Oracle(csv), key, sig, [], ALPHA / 2)["base"]["lam_known"]
    pv = 0.25  # (0.5 °C)²
    coarse = separability(ChannelOracle(csv, slope, steps, pv), key, sig, [],
                          ALPHA / 2)["base"]["lam_known"]
    none = separability(ChannelOracle(csv, slope, steps, 0.0), key, sig, [],
                        ALPHA / 2)["base"]["lam_known"]
    assert plain > 10.0
    np.testing.assert_allclose(none, plain, rtol=1e-9)
    assert coarse < 0.3**2 / pv * 1.01  # the plateau's rounding takes it


def test_an_outlier_in_student_t_means_is_judged_against_that_tail():
    # gen3 sizes an outlier from the Gaussian σ of a mean; among 700 means drawn from t_5 a
    # reading that far off is a chance event, and the χ² threshold called it detectable
    from scipy import stats as sps

    from benchmarks.blind.gen3.separable import tail_power

    level, n = ALPHA / 2, 700
    gauss = sps.ncx2.sf(sps.chi2.isf(level / n, 3), 3, 100.0)
    assert tail_power(100.0, 3, level, n, float("inf")) == gauss > 0.99
    assert tail_power(100.0, 3, level, n, 5.0) < 0.01
    assert tail_power(100.0, 3, level, n, 1e4) > 0.98  # a t with ν → ∞ is Gaussian


def test_the_family_multiplicity_counts_testable_families_and_the_effects_own_grid(tmp_path):
    from benchmarks.blind.gen3.separable import family_multiplicity

    drawn, _ = draw_effect("session_offset", _staircase(5), 2.0)
    csv = tmp_path / "case.csv"
    write_csv(simulate(drawn.case, drawn), csv)
    ctx = Oracle(csv).ctx
    k, g = family_multiplicity(ctx, "session_offset")
    testable = [e for e in ("session_offset", "outlier", "thermal_hysteresis")
                if BY_ID[e].identifiable(ctx)[0]]
    assert "thermal_hysteresis" not in testable  # one way: the direction never changes
    assert 2 <= k < 15 and g == max(len(BY_ID["session_offset"].grid(ctx)), 1) >= 2
    assert family_multiplicity(ctx, "outlier") == (k, ctx.n)
