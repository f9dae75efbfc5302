"""One resting board whose bias drifts by tens of mg with temperature is one orientation.

The gate's leader clustering (2° or the noise's angle) split a consumer part at
1.5-2 mg/°C over a 30 °C warm-up (50-80 mg: 3-4.5°) into several "orientations": each
took its own gravity constant, so the bias change between them was lost, and a heater
warm-up (the clusters at separate temperatures) was refused as re-placed faces. The
warm-up fit joins clusters a continuous drift connects (no jump between consecutive
captures) and keeps a re-placement, or a slow tilt beyond any bias tempco, apart.

Logs: 1-s capture rows (t_s, sensor_c, ax, ay, az, n, sd), a die heating 10 → 40 °C
with τ 5 min over 30 min, 0.1 mg capture noise.
"""

from __future__ import annotations

import numpy as np

from calibration.fitting import fit
from calibration.gate import GateRefusal, distinct_orientations
from calibration.recording import Recording

DURATION_S = 1800.0
TEMPCO_G_PER_C = np.array([1.8e-3, -1.5e-3, 0.3e-3])  # a consumer part's upper end
NOISE_G = 0.1e-3


def _rows(acc: np.ndarray, die: np.ndarray, t: np.ndarray, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    acc = acc + rng.normal(0.0, NOISE_G, acc.shape)
    n = np.full(t.size, 100.0)
    sd = np.full(t.size, NOISE_G * 10.0)
    return Recording.from_columns({
        "t_s": t, "sensor_c": die + rng.normal(0.0, 0.01, t.size),
        "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2], "n": n,
        "sd_x": sd, "sd_y": sd, "sd_z": sd})


def _heater() -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, DURATION_S, 1.0)
    return t, 10.0 + 30.0 * (1.0 - np.exp(-t / 300.0))


def test_a_drifting_bias_is_one_orientation_and_its_change_is_fitted() -> None:
    t, die = _heater()
    acc = np.array([0.0, 0.0, 1.0]) + (die - 25.0)[:, None] * TEMPCO_G_PER_C
    rec = _rows(acc, die, t)
    # the premise: the gate's clustering alone splits it
    assert distinct_orientations(rec.raw_g, rec.sigma_g).count >= 2
    result = fit(rec)
    assert result.kind == "warmup"
    assert result.report["orientations"] == 1
    # what a person reads says the same: one orientation, joined from the clusters
    assert result.orientations == 1
    assert "the fit joins them" in result.reason and "joined into 1 orientation" in result.reason
    assert any("joined into 1 orientation" in n for n in result.report["notes"])
    change = result.report["bias_change_mg"]
    expected = (die.max() - die.min()) * TEMPCO_G_PER_C * 1e3
    np.testing.assert_allclose([change["bx"], change["by"], change["bz"]], expected,
                               atol=0.1)


def test_a_re_placed_board_is_still_two_orientations() -> None:
    """The same drifting part, but the board is turned by 10° half-way: a jump between
    two consecutive captures, not a drift. Two orientations (or a refusal), never one."""
    t, die = _heater()
    tilt = np.radians(np.where(t < DURATION_S / 2, 0.0, 10.0))
    acc = (np.column_stack([np.sin(tilt), 0.0 * t, np.cos(tilt)])
           + (die - 25.0)[:, None] * TEMPCO_G_PER_C)
    try:
        result = fit(_rows(acc, die, t))
    except GateRefusal:
        return
    assert result.report["orientations"] >= 2
    assert not any("joined into 1 orientation" in n for n in result.report["notes"])


def test_a_slow_tilt_beyond_any_bias_tempco_is_not_joined() -> None:
    """A board creeping through 25° while the die rises 30 °C is not a bias change (the
    most any MEMS offset moves, 5 mg/°C on two axes, turns it by 12°): kept apart."""
    t, die = _heater()
    tilt = np.radians(25.0 * t / DURATION_S)
    acc = np.column_stack([np.sin(tilt), 0.0 * t, np.cos(tilt)])
    rec = _rows(acc, die, t)
    try:
        result = fit(rec)
    except GateRefusal:
        return
    assert result.report["orientations"] >= 2
    assert not any("joined into 1 orientation" in n for n in result.report["notes"])
