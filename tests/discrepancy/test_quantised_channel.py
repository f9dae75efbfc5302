"""A temperature channel quantised without dither: its shared error is known (issue 22).

A channel quantised to q whose own noise is far below q records one code for every reading
of a settled plateau, so the plateau's readings share one rounding error, uniform in ±q/2.
Sign flips per reading cannot reproduce an error a plateau shares, so a column constant
within plateaus (a channel step) ran above its level. The grid is read from the recording
(plateau_noise.temperature_grid) and the null draws the error at its known variance q²/12
through ∂output/∂T (plateau_noise.quantised_channel, stats.wild_replicates(known=...)).
"""

import numpy as np
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.generate import _channel
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose, stats
from calibration.discrepancy.plateau_noise import (
    _decimals,
    held_code_resolution_c,
    one_code_per_plateau,
    temperature_grid,
)
from calibration.recording import Recording
from tests.discrepancy.plateau_layout import plateau_layout

K, PER, N_SAMPLES = 8, 18, 50


def _channel_values(rng, lsb, sd, offset=0.0, setpoints=None, drift=0.3):
    """Capture means (3 decimals) of a channel quantised to ``lsb`` with per-sample noise
    ``sd``, the die settling by ``drift`` °C over each plateau."""
    sp = np.linspace(-30.0, 60.0, K) if setpoints is None else np.asarray(setpoints, float)
    step = np.repeat(np.arange(K), PER)
    die = sp[step] + offset - drift * np.exp(-np.tile(np.arange(PER), K) / 6.0) \
        + rng.uniform(-0.5, 0.5, K)[step]
    draws = die[:, None] + sd * rng.standard_normal((die.size, N_SAMPLES))
    return np.round(np.mean(np.round(draws / lsb) * lsb, axis=1), 3), step


def test_the_grid_of_a_clean_channel_is_found_and_a_dithered_one_has_none():
    rng = np.random.default_rng(3)
    t, step = _channel_values(rng, 0.1, 0.003)
    g = temperature_grid(t, step)
    assert g is not None and abs(g.q_c - 0.1) < 1e-9 and g.fraction > 0.9
    t, step = _channel_values(rng, 0.1, 0.04)  # dithered: the means fall between codes
    assert temperature_grid(t, step) is None
    t, step = _channel_values(rng, 0.01, 0.02)  # a chamber PV at 0.01 °C: no grid
    assert temperature_grid(t, step) is None
    # A 0.0625 °C part written to 3 decimals (0.062 or 0.063 between codes), with an offset.
    t, step = _channel_values(rng, 0.0625, 0.002, offset=3.3)
    g = temperature_grid(t, step)
    assert g is not None and abs(g.q_c - 0.0625) < 5e-4


def test_codes_that_are_the_setpoints_alone_do_not_give_a_spacing():
    """A channel that never leaves one code per plateau, the codes whole degrees apart:
    the recording does not say whether q is 0.1 or 1 °C, so no grid is claimed; that the
    channel does not dither is still seen (one_code_per_plateau)."""
    step = np.repeat(np.arange(K), PER)
    t = np.array([-30.0, -17.0, -4.0, 9.0, 22.0, 35.0, 48.0, 61.0])[step]
    assert temperature_grid(t, step) is None
    assert one_code_per_plateau(t, step)
    rng = np.random.default_rng(4)
    t, step = _channel_values(rng, 0.1, 0.04)  # dithered
    assert not one_code_per_plateau(t, step)


def _layout():
    return plateau_layout(K, PER)


def test_the_known_rounding_error_restores_the_level_of_a_channel_step():
    """One rounding error per plateau (sd q/√12 = 1 noise unit through the loading): a
    channel step from plateau K/2 on is far above its level against sign flips, at it
    with the known draw."""
    rng = np.random.default_rng(11)
    n, step, row, axis, U = _layout()
    load = np.array([1.0, -0.6, 0.4])[axis]  # whitened ∂output/∂T per °C, by axis
    q = 0.1
    load = load / (q / np.sqrt(12.0))  # the rounding error is one noise unit
    sg = stats.SharedGroups([load], [step[row]], ["quantised temperature channel"])
    X = (load * (step[row] >= K // 2))[:, None]
    R, B = 150, 200
    p_wild, p_known = [], []
    for _ in range(R):
        y = rng.standard_normal(3 * n) + load * rng.uniform(-q / 2, q / 2, K)[step[row]]
        e = stats.project_out(U, y)
        lp = stats.linear_stats(U, X, e, np.zeros((3 * n, 1)))[0]
        W = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, B)))
        Q = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, B)),
                                  known=(sg, np.array([q**2 / 12.0])))
        for p, E in ((p_wild, W), (p_known, Q)):
            lpn = stats.linear_stats(U, X, e, E)[1]
            p.append((1 + np.sum(lpn <= lp)) / (B + 1))
    p_wild, p_known = np.array(p_wild), np.array(p_known)
    assert np.mean(p_wild <= 0.05) > 0.25
    assert np.mean(p_known <= 0.05) < 0.10


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def _record(channel: str) -> Recording:
    rng = np.random.default_rng(7)
    pr = protocol.draw_protocol(rng, kind="updown", schedule="sparse18", columns=("sensor_c",),
                                soak_min=45.0)
    pr = _channel(pr, {"temperature_channel": channel} if channel != "dithered" else {})
    sensor = draw_sensor(rng)
    pat = {**fx.pattern(rng, len(pr.setpoints_c), 10), "rows": [0, 1]}
    return Recording.from_columns(sim.record(pr, sensor, _pools(), None, 0.0, pat, 7))


def test_the_generator_s_clean_channel_and_what_diagnose_says_of_it():
    """gen2's --temperature-channel clean: the same recording but for the channel, which
    sits on its 0.1 °C codes; diagnose names the grid and what the null does with it, and
    says nothing of the kind on the default (dithered) channel."""
    clean, dithered = _record("clean"), _record("dithered")
    for c in ("ax", "ay", "az", "t_s"):
        np.testing.assert_array_equal(clean.columns[c], dithered.columns[c])
    t = clean.columns["sensor_c"]
    assert np.mean(np.abs(t / 0.1 - np.round(t / 0.1)) < 0.02) > 0.8
    note = [x for x in diagnose(clean, n_null=50).notes if "quantised" in x]
    assert len(note) == 1 and "0.1 °C without dither" in note[0] \
        and "known to ±0.05 °C" in note[0] and "the null includes" in note[0] \
        and "declare its LSB, sensor_lsb_c" in note[0]
    assert not [x for x in diagnose(dithered, n_null=50).notes if "quantised" in x]


def _held(codes_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A channel that holds one code per plateau (``codes_c``), its first plateau an
    approach whose capture means are written to 3 decimals."""
    step = np.repeat(np.arange(K), PER)
    t = np.asarray(codes_c, float)[step]
    t[:3] = np.round(codes_c[0] + 0.3 * np.exp(-np.arange(3) / 1.5), 3)
    return t, step


def test_codes_off_whole_degrees_bound_the_lsb_from_below_and_setpoints_do_not():
    """A channel that holds one value per plateau shows no grid; its codes written to 0.1 °C
    and not all whole degrees put q at 0.1 °C at least (the approach's 3-decimal means say
    nothing of it); codes that are the whole-degree setpoints bound nothing."""
    sp = np.linspace(-30.0, 60.0, K).round()
    t, step = _held(sp - 0.1)
    assert temperature_grid(t, step) is None and one_code_per_plateau(t, step)
    assert _decimals(t) == 3  # all the readings' resolution: the approach's, no bound
    assert held_code_resolution_c(t, step) == 0.1
    t, step = _held(sp)
    assert one_code_per_plateau(t, step) and held_code_resolution_c(t, step) is None
    rng = np.random.default_rng(5)
    t, step = _channel_values(rng, 0.1, 0.04)  # dithered: no code held
    assert held_code_resolution_c(t, step) is None


def test_diagnose_draws_the_held_codes_resolution_and_says_it_is_a_least_error():
    """The generator's clean channel held on one code per plateau: written to 0.1 °C off the
    setpoints, the null draws that rounding and the note says it is the least; on the
    setpoints themselves, the note says the LSB is unknown and nothing is drawn."""
    clean = _record("clean")
    held = np.asarray(clean.columns["setpoint_c"], float)  # whole degrees here
    assert np.all(held == np.round(held))
    for codes, says in ((held - 0.1, ("codes are written to 0.1 °C", "±0.05 °C at best",
                                       "the null includes that least error")),
                        (held, ("whole degrees, bound nothing", "null does not include"))):
        rec = Recording.from_columns({**clean.columns, "sensor_c": codes})
        note = [x for x in diagnose(rec, n_null=50).notes if "holds one value" in x]
        assert len(note) == 1 and all(w in note[0] for w in says), note
