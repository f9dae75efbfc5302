"""The throughput bench mounts its own parts, one per serial, in one chamber (issue 12)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.bench_soak_time import BenchTruth, heldout_errors_g, make_truth
from benchmarks.bench_throughput import make_truths, rate_of, run_several, serials_for


def test_every_serial_gets_its_own_bench_truth_and_rate() -> None:
    truths = make_truths(4, [0.0, 100.0], probe_n=8)
    assert list(truths) == serials_for(4)
    assert [t.serial for t in truths.values()] == serials_for(4)  # the twin's identity
    assert [t.crn_seed for t in truths.values()] == [1, 2, 3, 4]  # own noise streams
    assert [rate_of(i, [0.0, 100.0]) for i in range(4)] == [0.0, 100.0, 0.0, 100.0]
    assert truths["SN-T0001"].rate_g_per_c_per_s is None
    assert truths["SN-T0002"].rate_g_per_c_per_s is not None


async def test_a_two_step_campaign_calibrates_each_sensor_against_its_own_truth(
        tmp_path: Path) -> None:
    truths = make_truths(2, [0.0], probe_n=8)
    spec = {"setpoints_c": [20.0, 30.0], "soak_min": 1, "stability": "fixed",
            "positions": "table1", "samples_per_position": 50, "ramp_c_per_min": 5.0}
    fits, sim_s, log, dropped = await run_several(spec, tmp_path, truths)
    assert dropped == {} and sorted(fits) == serials_for(2) and len(log) == 2
    # One shared chamber reached every truth (the rate effect's die rate).
    chambers = {id(t.chamber) for t in truths.values()}
    assert len(chambers) == 1 and all(t.chamber is not None for t in truths.values())
    assert all(isinstance(t, BenchTruth) and t._attempts for t in truths.values())
    temps = np.array([25.0])
    own = [make_truth(1, False, 0.0), make_truth(2, False, 0.0)]
    for i, serial in enumerate(serials_for(2)):
        mine = np.sqrt(np.mean(heldout_errors_g(fits[serial].model, own[i], temps) ** 2))
        other = np.sqrt(np.mean(heldout_errors_g(fits[serial].model, own[1 - i], temps) ** 2))
        # A fit of its own part is far closer to it than to the other part (mg offsets).
        assert mine < 0.1 * other


def test_a_crn_offset_keeps_the_parts_and_changes_only_the_noise_streams() -> None:
    base = make_truths(2, [0.0], probe_n=8)
    other = make_truths(2, [0.0], probe_n=8, crn_offset=1)
    assert [t.crn_seed for t in other.values()] == [1001, 1002]
    for serial in base:
        assert base[serial].temp_offset_c == other[serial].temp_offset_c
        ref = np.array([[0.0, 0.0, 1.0]])
        assert np.allclose(base[serial].ideal_raw_g(ref, 20.0),
                           other[serial].ideal_raw_g(ref, 20.0))


def test_a_position_gets_the_same_noise_whatever_order_the_step_visits_it_in() -> None:
    """Common random numbers keyed by (sensor, orientation, setpoint, attempt): two policies
    visiting a step's positions in other orders still measure each position with the same
    noise (keyed by the capture's index, a reordered step drew other noise for every
    position), and a quality re-measure of a position draws its own."""
    from types import SimpleNamespace

    refs = [np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0])]

    def captures(order: list[int]) -> dict[int, np.ndarray]:
        truth = make_truth(3, False, 0.0, probe_n=8)
        truth.chamber = SimpleNamespace(setpoint_c=10.0, air_c=10.0, die_c=10.0,
                                        die_tau_s=900.0)
        rng = np.random.default_rng(0)
        return {i: truth.sample_g(refs[i], 10.0, 50, rng) for i in order}

    forward, backward = captures([0, 1, 2]), captures([2, 0, 1])
    for i in range(3):
        assert np.array_equal(forward[i], backward[i])
    truth = make_truth(3, False, 0.0, probe_n=8)
    truth.chamber = SimpleNamespace(setpoint_c=10.0, air_c=10.0, die_c=10.0, die_tau_s=900.0)
    rng = np.random.default_rng(0)
    first, again = (truth.sample_g(refs[0], 10.0, 50, rng) for _ in range(2))
    assert np.array_equal(first, forward[0]) and not np.array_equal(first, again)
    truth.chamber.setpoint_c = 20.0  # the next step: other noise for the same position
    assert not np.array_equal(truth.sample_g(refs[0], 10.0, 50, rng), first)


def test_the_noise_free_log_is_each_capture_without_its_noise() -> None:
    """``BenchTruth.noise_free_log`` (the soak-only refits of bench_heldout_steps): each
    position capture's key and mean output less the accelerometer noise, the rate effect
    included; a soak probe (the probe size) is not logged."""
    from types import SimpleNamespace

    from benchmarks.bench_heldout_steps import noise_free_columns

    truth = make_truth(3, False, 100.0, probe_n=250)
    truth.chamber = SimpleNamespace(air_c=-38.0, die_c=-39.0, die_tau_s=900.0, setpoint_c=-40.0)
    ref = np.array([0.0, 0.0, 1.0])
    rng = np.random.default_rng(0)
    out = truth.sample_g(ref, -39.0, 200, rng)
    truth.sample_g(ref, -39.0, 250, rng)  # a probe: not logged
    (key, ideal), = truth.noise_free_log
    rate_g = (1.0 / 900.0) * truth.rate_g_per_c_per_s  # (air − die) / τ, °C/s
    assert np.allclose(ideal, truth.ideal_raw_g(ref[None, :], -39.0)[0] + rate_g)
    # what is left is the noise of a 200-sample mean (140 µg per sample): within 5 σ
    assert np.all(np.abs(out.mean(axis=0) - ideal) < 5 * truth.sample_sd_g() / np.sqrt(200))
    # the rows get their capture's noise-free mean back, matched by reference and setpoint
    cols = {"t_s": [1.0], "step": [0.0], "setpoint_c": [-40.0], "ref_x": [0.0], "ref_y": [0.0],
            "ref_z": [1.0], "ax": [9.0], "ay": [9.0], "az": [9.0], "n": [200.0]}
    got = noise_free_columns(cols, truth.noise_free_log)
    assert got is not None and [got["ax"][0], got["ay"][0], got["az"][0]] == list(ideal)
    assert noise_free_columns({**cols, "setpoint_c": [-30.0]}, truth.noise_free_log) is None
