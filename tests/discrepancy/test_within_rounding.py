"""A channel step within the rounding the channel's codes admit is not named (issue 22).

A channel that does not dither and holds whole-degree codes (a die settled on setpoints
that lie on codes) could round at 1 °C or at 0.1 °C: the recording cannot say. The die ends
each plateau short of its setpoint with the approach's sign, so code − die makes a step of
the channel between the legs; within what a rounding of ±Q/2 per plateau can make, it is
reported as not established (declare the LSB), not named ``temperature_sensor``.
"""

import numpy as np

from calibration.discrepancy import diagnose, scan, stats
from calibration.discrepancy.plateau_noise import admitted_lsb_c
from calibration.recording import Recording
from tests.discrepancy.test_quantised_channel import PER, K, _channel_values, _held, _record


def test_the_coarsest_lsb_the_held_codes_admit():
    """Whole-degree codes admit 1 °C, whatever an approach plateau's 3-decimal means say;
    codes written to 0.1 °C admit 0.1 °C; a dithered channel holds no code."""
    sp = np.linspace(-30.0, 60.0, K).round()
    t, step = _held(sp)
    assert admitted_lsb_c(t, step) == 1.0
    t, step = _held(sp - 0.1)
    assert np.isclose(admitted_lsb_c(t, step), 0.1)
    t, step = _channel_values(np.random.default_rng(5), 0.1, 0.04)
    assert admitted_lsb_c(t, step) is None
    assert PER >= 3


def test_a_channel_step_within_whole_degree_codes_rounding_is_not_named():
    """The generator's die on an up-down staircase (45-min soaks) read by a 1 °C channel
    that does not dither (its 0.1 °C channel rounded to whole degrees): the die ends each
    plateau short of its setpoint with the approach's sign, and that rounding's leg
    pattern was named a channel step; now no mismatch, the step listed not established
    with the reason and the column to declare. A channel step of 0.3 °C, which moves the
    codes off whole degrees, is still named."""
    clean = _record("clean")
    held = np.round(np.asarray(clean.columns["sensor_c"], float))
    rec = Recording.from_columns({**clean.columns, "sensor_c": held})
    d = diagnose(rec, n_null=50)
    assert not d.mismatch, [f.effect for f in d.findings]
    listed = [n for n in d.not_identifiable if n["effect"] == "temperature_sensor"]
    assert len(listed) == 1 and "within the channel's possible rounding" in listed[0]["why"] \
        and "LSB of 1 °C" in listed[0]["why"] and "sensor_lsb_c" in listed[0]["why"]
    assert any("temperature_sensor not named" in x for x in d.notes)
    step = np.asarray(clean.columns["step"])
    shifted = held + np.where(step >= step.max() // 2, 0.3, 0.0)
    d = diagnose(Recording.from_columns({**clean.columns, "sensor_c": shifted}), n_null=50)
    assert d.findings and d.findings[0].effect == "temperature_sensor"


def test_a_scan_block_s_reach_is_the_box_s_reach_of_its_projected_columns():
    """scan._block_reach (from the block's support and the box's group sums of U) equals the
    box's reach on the block's full projected orthonormal columns."""
    rng = np.random.default_rng(3)
    m, p = 60, 5
    U = np.linalg.qr(rng.standard_normal((m, p)))[0]
    box = stats.BoundedShared(np.repeat(np.arange(6), 10), rng.standard_normal(m), 0.05)
    S = np.arange(20, 32)
    Xs = rng.standard_normal((S.size, 2))
    UX = U[S].T @ Xs
    lam, V = np.linalg.eigh(Xs.T @ Xs - UX.T @ UX)
    W = V / np.sqrt(lam)
    X = np.zeros((m, 2))
    X[S] = Xs
    B = (X - U @ (U.T @ X)) @ W
    assert np.allclose(B.T @ B, np.eye(2))
    got = scan._block_reach(box, box.group_sums(U), S, Xs @ W, UX @ W)
    assert np.isclose(got, box.reach(B))
