"""A quantised channel's rounding error is bounded, not random (issue 22).

A channel quantised to q without dither records code − die, within ±q/2. A die still
settling towards setpoints that lie on codes has that error with the approach's sign on
every plateau of a leg: up to q of channel step between the legs, a pattern that one
Gaussian draw per plateau at q²/12 rarely makes (the clean-channel nulls that fired at
p = 1e-10 … 1e-44). The families' F tests take the data's score net of the most any error
in the box can put into it (stats.BoundedShared, stats.linear_stats(bounded=...)).
"""

import numpy as np
import pytest
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose, stats
from calibration.errors import RecordingError
from calibration.recording import Recording, read_recording, write_recording
from calibration.temperature_lsb import declared_lsb_c
from tests.discrepancy.plateau_layout import plateau_layout

K, PER = 8, 18


def _updown_layout(k: int, per: int):
    """:func:`plateau_layout` on an up-down staircase: the plateaus of the second leg
    revisit the first's temperatures in reverse (the base model, a cubic per axis in
    temperature, cannot take a difference between the legs)."""
    n, step, row, axis, _ = plateau_layout(k, per)
    up = np.linspace(-1.0, 1.0, k // 2)
    t = np.concatenate([up, up[::-1]])[step] + 0.01 * np.tile(np.linspace(-1, 1, per), k)
    X0 = np.zeros((3 * n, 12))
    for a in range(3):
        X0[axis == a, 4 * a:4 * a + 4] = np.vander(t[row[axis == a]], 4, increasing=True)
    return n, step, row, axis, stats.orthonormal_basis(X0)


def _approach_error(q: float, k: int) -> np.ndarray:
    """Per-plateau rounding error of a die settling towards codes: 0.7·q/2 short of the
    setpoint on every plateau, up the first half, down the second (the sign of approach)."""
    return np.where(np.arange(k) < k // 2, 0.35 * q, -0.35 * q)


def test_the_bound_holds_a_channel_step_s_level_where_a_random_draw_does_not():
    """Whitened, q/√12 is one noise unit through the loading. Against sign flips with the
    rounding error drawn at random per plateau (its variance known), the approach's error
    makes a channel step between the legs significant far above the level; net of the
    box's reach, never above it."""
    rng = np.random.default_rng(5)
    n, step, row, axis, U = _updown_layout(K, PER)
    q = 0.1
    load = np.array([1.0, -0.6, 0.4])[axis] / (q / np.sqrt(12.0))
    group = step[row]
    sg = stats.SharedGroups([load], [group], ["quantised temperature channel"])
    box = stats.BoundedShared(group, load, q / 2.0)
    X = (load * (group >= K // 2))[:, None]
    delta = _approach_error(q, K)
    R, B = 120, 200
    p_known, p_box = [], []
    for _ in range(R):
        y = rng.standard_normal(3 * n) + load * delta[group]
        e = stats.project_out(U, y)
        Q = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, B)),
                                  known=(sg, np.array([q**2 / 12.0])))
        lp, lpn = stats.linear_stats(U, X, e, Q)[:2]
        p_known.append((1 + np.sum(lpn <= lp)) / (B + 1))
        W = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, B)))
        lp, lpn = stats.linear_stats(U, X, e, W, bounded=box)[:2]
        p_box.append((1 + np.sum(lpn <= lp)) / (B + 1))
    assert np.mean(np.array(p_known) <= 0.05) > 0.5
    assert np.mean(np.array(p_box) <= 0.05) <= 0.05


def test_a_step_well_beyond_the_box_is_still_found():
    """Power where the data allow it: a channel step of 3 LSB on top of the rounding error
    stays significant net of the box (one-sided too: a lag's amplitude column)."""
    rng = np.random.default_rng(6)
    n, step, row, axis, U = _updown_layout(K, PER)
    q = 0.1
    load = np.array([1.0, -0.6, 0.4])[axis] / (q / np.sqrt(12.0))
    group = step[row]
    box = stats.BoundedShared(group, load, q / 2.0)
    X = (load * (group >= K // 2))[:, None]
    delta = _approach_error(q, K) + 0.3 * (np.arange(K) >= K // 2)
    y = rng.standard_normal(3 * n) + load * delta[group]
    e = stats.project_out(U, y)
    W = stats.wild_replicates(rng, e, U, row, np.empty((3 * n, 200)))
    for one_sided in (False, True):
        lp_free = stats.linear_stats(U, X, e, W, one_sided)[0]
        lp_box, lpn = stats.linear_stats(U, X, e, W, one_sided, bounded=box)[:2]
        assert lp_free < lp_box < np.log(1e-6)
        assert np.all(lpn > lp_box)


def test_the_reach_is_exact_for_one_column_and_an_upper_bound_for_more():
    rng = np.random.default_rng(7)
    m, g = 60, 6
    group = np.repeat(np.arange(g), m // g)
    load = rng.standard_normal(m)
    box = stats.BoundedShared(group, load, 0.5)
    B = np.linalg.qr(rng.standard_normal((m, 3)))[0]
    corners = np.array(np.meshgrid(*[[-0.5, 0.5]] * g)).reshape(g, -1).T  # every vertex
    Z = np.zeros((m, g))
    Z[np.arange(m), group] = load
    worst1 = np.max(np.abs(corners @ (Z.T @ B[:, 0])))
    assert box.reach(B[:, :1]) == pytest.approx(worst1)
    worst3 = np.max(np.linalg.norm(corners @ (Z.T @ B), axis=1))
    assert worst3 <= box.reach(B) + 1e-12


def _pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


SETPOINTS = (-20.0, -5.0, 10.0, 25.0, 40.0, 55.0, 70.0, 55.0, 40.0, 25.0, 10.0, -5.0, -20.0)


def _settling_null(seed: int) -> dict[str, np.ndarray]:
    """gen2's clean channel (0.1 °C, no dither) on an up-down staircase whose die (τ 470 s,
    45 min soaks) ends each plateau ~0.03 °C short of its setpoint: every reading of a
    plateau on the setpoint's code, the error of the approach's sign — and no LSB shown
    (no plateau moves by a code)."""
    pr = protocol.Protocol2("updown/settling", SETPOINTS, 45.0, "sparse18", ("sensor_c",),
                            470.0, 200, (0.0,) * len(SETPOINTS), False, None, 5.7e-5,
                            sensor_c_sd_c=sim.CLEAN_CH_SD_C)
    rng = np.random.default_rng(seed)
    sensor = draw_sensor(rng)
    pat = {**fx.pattern(rng, len(SETPOINTS), 10), "rows": [0, 1]}
    return sim.record(pr, sensor, _pools(), None, 0.0, pat, seed)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_settling_die_on_a_declared_channel_is_no_mismatch(seed):
    """The recording declares its LSB (``sensor_lsb_c``): no mismatch (before: a channel
    step between the legs at p ≈ 1e-11). Without the column the LSB is not shown and the
    step is (still) reported, or, within the rounding of the coarsest LSB the codes admit,
    listed as not established (within_rounding.py) — what the column is for."""
    cols = _settling_null(seed)
    d = diagnose(Recording.from_columns(cols), seed=1, n_null=100)
    assert d.mismatch or [n for n in d.not_identifiable if n["effect"] == "temperature_sensor"
                          and "possible rounding" in n["why"]]
    cols["sensor_lsb_c"] = np.full(len(cols["t_s"]), 0.1)
    d = diagnose(Recording.from_columns(cols), seed=1, n_null=100)
    assert not d.mismatch, [(f.effect, f.p_value) for f in d.findings]
    note = [x for x in d.notes if "quantised at 0.1 °C declared" in x]
    assert len(note) == 1 and "±0.05 °C" in note[0]


def test_the_declared_lsb_column_is_read_from_a_file_and_checked(tmp_path):
    cols = {"t_s": np.arange(4.0), "ax": np.zeros(4), "ay": np.zeros(4), "az": np.ones(4),
            "sensor_c": np.array([20.0, 20.0, 30.0, 30.0])}
    path = tmp_path / "r.csv"
    write_recording(path, {**cols, "sensor_lsb_c": np.full(4, 0.0625)})
    rec = read_recording(path)
    assert declared_lsb_c(rec, "sensor_c") == 0.0625
    assert declared_lsb_c(rec, "chamber_c") is None
    write_recording(path, cols)
    assert declared_lsb_c(read_recording(path), "sensor_c") is None
    for bad, line in (([0.1, 0.1, 0.2, 0.1], 4), ([0.1, -0.1, 0.1, 0.1], 3),
                      ([0.1, 0.1, 0.1, 20.0], 5)):
        write_recording(path, {**cols, "sensor_lsb_c": np.array(bad)})
        with pytest.raises(RecordingError) as err:
            declared_lsb_c(read_recording(path), "sensor_c")
        assert err.value.line == line and err.value.column == "sensor_lsb_c"


def test_a_reading_s_reach_bounds_every_corner_of_the_box(monkeypatch):
    """row_stats' per-reading reach: no error in the box moves a reading's residual (after
    the base model's projection, in its covariance's metric) further; the cheap bound of
    long recordings is larger still."""
    rng = np.random.default_rng(8)
    n, g, k = 12, 3, 4
    group = np.repeat(np.arange(n) // (n // k), g)  # four plateaus of three readings
    load = rng.standard_normal(n * g)
    U = np.linalg.qr(rng.standard_normal((n * g, 5)))[0]
    idx = np.arange(n * g).reshape(n, g)
    A = rng.standard_normal((n, g, g))
    Minv = A @ np.transpose(A, (0, 2, 1)) + np.eye(g)[None]
    box = stats.BoundedShared(group, load, 0.5)
    reach = box.reading_reach(U, idx, Minv)
    Z = np.zeros((n * g, k))
    Z[np.arange(n * g), group] = load
    R = stats.project_out(U, Z)
    corners = np.array(np.meshgrid(*[[-0.5, 0.5]] * k)).reshape(k, -1).T
    moved = (R @ corners.T)[idx]  # (n, g, corners)
    worst = np.sqrt(np.einsum("ngc,ngh,nhc->nc", moved, Minv, moved)).max(axis=1)
    assert np.all(worst <= reach + 1e-12) and np.all(reach < 4 * worst)
    monkeypatch.setattr(stats, "REACH_BUDGET", 0)
    assert np.all(box.reading_reach(U, idx, Minv) >= reach - 1e-12)


def test_an_own_test_sees_the_box_through_the_shortened_residual():
    """An effect with its own F (turntable_geometry's) is handed the residual whose part
    along its columns is shortened by the reach: for a statistic of (Bᵀe, (I − BBᵀ)e) that
    is the score linear_stats takes net of the box."""
    rng = np.random.default_rng(9)
    n, step, row, axis, U = _updown_layout(K, PER)
    load = np.array([1.0, -0.6, 0.4])[axis] * 30.0
    group = step[row]
    box = stats.BoundedShared(group, load, 0.05)
    X = np.column_stack([load * (group >= K // 2), rng.standard_normal(3 * n)])
    e = stats.project_out(U, rng.standard_normal(3 * n) + 0.5 * X[:, 0])
    E = rng.standard_normal((3 * n, 4))
    B = stats.orthonormal_basis(stats.project_out(U, X), 1e-6)
    net = stats.linear_stats(U, X, e, E, bounded=box)[0]
    assert stats.linear_stats(U, X, box.shortened(B, e), E)[0] == pytest.approx(net)
    assert net > stats.linear_stats(U, X, e, E)[0]
