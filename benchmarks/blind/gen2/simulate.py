"""One recording of the second generator: timeline, die temperature, samples, capture means.

The rig: the chamber air ramps at 2 °C/min between setpoints and holds; the die follows the
air as a first-order lag (τ of the protocol, exact exponential per second); every capture
is n consecutive samples of the sensor's own real noise plus the bench's real disturbance
(zero mean), quantised to the ADXL355's 3.9 µg code, then averaged. Each visit re-seats the
sensor with a small random error (the real placement shape). The temperature channel is
quantised per sample (0.1 °C sensor channel, 0.01 °C chamber PV) and averaged per capture;
the sensor channel's own per-sample noise is the protocol's (0.04 °C by default: dithered).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol as pr
from benchmarks.blind.gen2 import unseen_effects as ux
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import Sensor2

LSB_G = 3.9e-6  # ADXL355 ±2 g code
PLACEMENT_RAD = 5e-6  # re-seating repeatability per visit and axis (rms): Protocol2's default
HAND_PLACED_RAD = 1e-4  # above this re-seating scatter the recording declares ref_tol_deg
SENSOR_CH_LSB_C, SENSOR_CH_SD_C = 0.1, pr.Protocol2.sensor_c_sd_c
CLEAN_CH_SD_C = 0.003  # a channel whose own noise is far below its LSB: it does not dither
CHAMBER_LSB_C, CHAMBER_SD_C = 0.01, 0.02
START_C = 25.0


@dataclass
class Scene:
    """Noise-free state of every reading (what detectability and the samples start from)."""

    steps: np.ndarray
    positions: np.ndarray
    t_s: np.ndarray
    air_c: np.ndarray
    die_c: np.ndarray
    die_rate_c_per_min: np.ndarray
    direction: np.ndarray
    session: np.ndarray
    ref_g: np.ndarray
    force_g: np.ndarray
    vib_sd_g: np.ndarray
    angles_rad: np.ndarray  # (N,2) α, β commanded
    crack_t_s: float
    die_trace_c: np.ndarray | None = None  # the die on the 1 s grid from t = 0 (frost)
    capture_s: float = 0.0  # one capture's length (fixture creep: the move ends before it)


def scene(proto: pr.Protocol2, eid: str | None, m: float, pat: dict, seed: int,
          die_tau_s: float | None = None) -> Scene:
    rng = np.random.default_rng(seed)
    ang = np.deg2rad(proto.angles_deg())
    cap_s = proto.n_samples / pr.FS_HZ
    rows, t = [], 0.0
    plateau_t: list[tuple[float, float, float]] = []  # (ramp start, ramp end, setpoint)
    prev = START_C
    for k, sp in enumerate(proto.setpoints_c):
        ramp_s = abs(sp - prev) / pr.RAMP_C_PER_MIN * 60.0
        plateau_t.append((t, t + ramp_s, sp))
        t += ramp_s + proto.soak_min * 60.0
        order = rng.permutation(len(ang)) if proto.irregular else np.arange(len(ang))
        if proto.irregular:
            order = order[rng.random(len(order)) > 0.1]
        for p in order:
            rows.append((k, int(p), t + pr.MOVE_S + cap_s / 2))
            t += pr.MOVE_S + cap_s
        prev = sp
    steps = np.array([r[0] for r in rows])
    pos = np.array([r[1] for r in rows])
    t_mid = np.array([r[2] for r in rows])
    grid = np.arange(0.0, t + 1.0, 1.0)
    air = np.full(grid.size, START_C)
    prev = START_C
    for t0, t1, sp in plateau_t:
        on = grid >= t0
        ramp = np.clip((grid - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)
        air = np.where(on, prev + (sp - prev) * ramp, air)
        prev = sp
    tau = die_tau_s if die_tau_s is not None else proto.die_tau_s
    if eid == "thermal_lag":
        tau = m
    a = np.exp(-1.0 / tau)
    die = np.empty_like(air)
    die[0] = air[0]
    for i in range(1, air.size):  # why a loop: exact first-order step, cheap at 1 s
        die[i] = air[i - 1] + (die[i - 1] - air[i - 1]) * a
    idx = np.clip(np.round(t_mid).astype(int), 1, grid.size - 2)
    rate = (die[idx + 1] - die[idx - 1]) / 2.0 * 60.0
    sp = np.array(proto.setpoints_c)
    prev_sp = np.concatenate([[START_C], sp[:-1]])
    direction = np.sign(sp - prev_sp)[steps]
    direction[direction == 0] = 1.0
    session = (steps >= proto.power_cycle_at).astype(float) if proto.power_cycle_at else \
        np.zeros(len(steps))
    alpha, beta = ang[pos, 0], ang[pos, 1]
    e_z = np.array([0.0, 0.0, 1.0])
    ref = np.array([pr.force_in_sensor(x, y, e_z) for x, y in zip(alpha, beta, strict=True)])
    up = fx.lab_up(eid or "", m, pat)
    beta_true = beta + fx.encoder_error_rad(eid or "", m, beta)
    force = np.array([pr.force_in_sensor(x, y, up) for x, y in zip(alpha, beta_true, strict=True)])
    k_c = pat["from_step"]
    on_k = t_mid[steps == k_c] if np.any(steps == k_c) else t_mid[-1:]
    crack_t = float(on_k.min() + pat["crack_frac"] * (on_k.max() - on_k.min()))
    return Scene(steps, pos, t_mid, air[idx], die[idx], rate, direction, session,
                 ref, force, np.array(proto.vib_sd_g)[steps], np.column_stack([alpha, beta]),
                 crack_t, die, cap_s)


def noise_free_output(sensor: Sensor2, sc: Scene, eid: str | None, m: float,
                      pat: dict) -> np.ndarray:
    state = {"force_g": sc.force_g, "direction": sc.direction, "t_h": sc.t_s / 3600.0,
             "session": sc.session, "die_rate_c_per_min": sc.die_rate_c_per_min,
             "vib_sd_g": sc.vib_sd_g, "t_s": sc.t_s, "crack_t_s": sc.crack_t_s,
             "ref_g": sc.ref_g, "die_c": sc.die_c, "die_trace_c": sc.die_trace_c,
             "angles_rad": sc.angles_rad, "capture_s": sc.capture_s}
    return (sensor.output_g(sc.force_g, sc.die_c) + fx.output_offset_g(eid or "", m, pat, state)
            + ux.unseen_offset_g(eid or "", m, pat, state))


def recorded_temperature_c(sc: Scene, proto: pr.Protocol2, eid: str | None, m: float,
                           pat: dict) -> dict[str, np.ndarray]:
    """Noise-free recorded channels (the channel step included)."""
    out = {}
    if "chamber_c" in proto.columns:
        out["chamber_c"] = sc.air_c.copy()
    if "sensor_c" in proto.columns:
        out["sensor_c"] = sc.die_c + fx.temperature_channel_shift_c(eid or "", m, pat,
                                                                    sc.steps)
        if proto.sensor_c_offset_c:  # the channel's own constant offset from the die
            out["sensor_c"] = out["sensor_c"] + proto.sensor_c_offset_c
    return out


def record(proto: pr.Protocol2, sensor: Sensor2, pools: NoisePools, eid: str | None, m: float,
           pat: dict, seed: int, die_tau_s: float | None = None) -> dict[str, np.ndarray]:
    """The recording's columns (capture means of noisy, quantised samples)."""
    rng = np.random.default_rng(seed + 1)
    sc = scene(proto, eid, m, pat, seed, die_tau_s)
    n = proto.n_samples
    # Each visit re-seats the sensor: a small rotation of the true force (real shape).
    ang = rng.choice(pools.placement, (len(sc.t_s), 3)) * proto.placement_rad
    force_seated = sc.force_g + np.cross(ang, sc.force_g)
    sc_seated = Scene(**{**sc.__dict__, "force_g": force_seated})
    mean_true = noise_free_output(sensor, sc_seated, eid, m, pat)
    means = np.empty_like(mean_true)
    sds = np.empty_like(mean_true)
    for i in range(len(sc.t_s)):
        x = (mean_true[i] + proto.sensor_noise_g * pools.block(rng, "sensor", n)
             + sc.vib_sd_g[i] * pools.block(rng, "vibration", n))
        for a in range(3):
            x[:, a] += fx.adc_band_error_g(eid or "", m, pat, x[:, a], a)
        x = np.round(x / LSB_G) * LSB_G
        means[i], sds[i] = x.mean(0), x.std(0, ddof=1)
    cols: dict[str, np.ndarray] = {
        "t_s": np.round(sc.t_s, 1), "step": sc.steps.astype(float),
        "setpoint_c": np.array(proto.setpoints_c)[sc.steps],
        "position": sc.positions.astype(float),
        "ref_x": sc.ref_g[:, 0], "ref_y": sc.ref_g[:, 1], "ref_z": sc.ref_g[:, 2],
        "ax": means[:, 0], "ay": means[:, 1], "az": means[:, 2], "n": np.full(len(sc.t_s), n),
        "sd_x": sds[:, 0], "sd_y": sds[:, 1], "sd_z": sds[:, 2]}
    for name, val in recorded_temperature_c(sc, proto, eid, m, pat).items():
        lsb, sd = ((proto.sensor_c_lsb_c, proto.sensor_c_sd_c) if name == "sensor_c"
                   else (CHAMBER_LSB_C, CHAMBER_SD_C))
        draws = val[:, None] + sd * rng.standard_normal((len(val), n))
        cols[name] = np.round(np.mean(np.round(draws / lsb) * lsb, axis=1), 3)
    if proto.placement_rad > HAND_PLACED_RAD:
        # A hand-placed fixture, declared as the format lets a lab do: the rms tilt of the
        # gravity direction (two axes across it) in degrees.
        tol = float(np.round(np.rad2deg(np.sqrt(2.0) * proto.placement_rad), 3))
        cols["ref_tol_deg"] = np.full(len(sc.t_s), tol)
    return cols


def reading_sigma_g(proto: pr.Protocol2, pools: NoisePools, sc: Scene) -> np.ndarray:
    """True scatter (N,3) of one capture mean as :func:`record` draws it: sensor + bench
    (their real correlation within a capture), quantisation, and the re-seating: three
    angle components of sd ``placement_rad`` crossed with the force, ρ²(1 − f_a²) on axis a
    (f the unit force)."""
    n = proto.n_samples
    v = (proto.sensor_noise_g**2 * pools.mean_variance("sensor", n)
         + sc.vib_sd_g**2 * pools.mean_variance("vibration", n) + LSB_G**2 / 12 / n)
    f = sc.ref_g / np.linalg.norm(sc.ref_g, axis=1, keepdims=True)
    return np.sqrt(v[:, None] + proto.placement_rad**2 * (1.0 - f**2))
