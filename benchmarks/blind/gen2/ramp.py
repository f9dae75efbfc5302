"""Ramp recordings of the second generator: the chamber never stops (issue 19's check).

A continuous ramp written on gen2's own pieces, none of the project's twin
(``simulators/``): the sensor is :class:`~benchmarks.blind.gen2.sensor.Sensor2` (Chebyshev
in temperature), the noise is drawn in contiguous blocks from the shared real recordings
(:mod:`~benchmarks.blind.gen2.realnoise`), the table angles, the ADXL355 code, the
re-seating error and the temperature channels are those of
:mod:`~benchmarks.blind.gen2.simulate`, and the rate sensitivity and hysteresis are
:func:`~benchmarks.blind.gen2.effects.output_offset_g` (``temperature_rate`` on the die's
rate, ``thermal_hysteresis`` on the chamber's direction). Nothing in gen2's other modules
is changed.

The rig: the chamber air follows one of two programs at ``rate_c_per_min`` (the die starts
settled where the air starts):

* ``program="lab"`` (default; issue 19's lab ramp): ``start → peak → end`` with no hold.
* ``program="plan"``: the legs soakcal's ramp plan commands, as docs/ramp-campaigns.md
  describes them (written here from the docs, not imported): from the rig's safe/ambient
  temperature ``safe_c`` to the low end, to the high end, back to ``safe_c``; at each of the
  two turnarounds the air holds until the die is within ``edge_gap_c`` of it (the plan's
  rule, which it measures on the dies; here the die is known), at least three blocks of
  half a sweep of captures and at most ``max_hold_min`` (the soak cap, 2 × ``soak_min``);
  no hold at the start or the end.

The die follows the air as gen2's first-order lag
(exact exponential per second); the table sweeps the schedule's positions over and over
(``MOVE_S`` between captures of ``n_samples`` at 100 Hz). Each row is one capture mean
stamped with its mean die temperature (``sensor_c``, 0.1 °C channel) and/or the chamber air
(``chamber_c``, 0.01 °C PV); no ``step`` or ``setpoint_c`` column: nothing is a plateau.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol as pr
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import Sensor2


@dataclass(frozen=True)
class RampSpec:
    """One ramp campaign of one sensor (defaults: issue 19's lab ramp)."""

    rate_c_per_min: float = 1.0
    start_c: float = -40.0
    peak_c: float = 60.0
    end_c: float = 25.0
    die_tau_s: float = 600.0
    schedule: str = "dense24"
    positions: tuple[int, ...] | None = None  # a subset of the schedule's; None: all of them
    n_samples: int = 100
    sensor_noise_g: float = 80e-6  # per-sample sd of the sensor's own noise
    vib_sd_g: float = 0.3e-3  # per-sample rms of the bench disturbance
    rate_ug_per_c_per_min: float = 0.0  # temperature_rate magnitude (die rate)
    hysteresis_ug: float = 0.0  # thermal_hysteresis magnitude (chamber direction)
    columns: tuple[str, ...] = ("chamber_c", "sensor_c")
    program: str = "lab"  # "lab": start → peak → end, no hold; "plan": soakcal's legs
    low_c: float = -40.0  # plan: the range's low end (the lowest setpoint)
    high_c: float = 60.0  # plan: the range's high end (the highest setpoint)
    safe_c: float = 25.0  # plan: where the chamber starts and ends (the rig's ambient/safe)
    edge_gap_c: float = 1.0  # plan: a turnaround hold ends with the die this close to the air
    min_hold_blocks: int = 3  # plan: a hold's captures at least this many blocks of half a sweep
    max_hold_min: float = 120.0  # plan: the hold cap (the soak cap, 2 × soak_min 60 min)


@dataclass
class RampTruth:
    """What the recording was made of: per row the true die temperature and rate."""

    die_c: np.ndarray
    die_rate_c_per_min: np.ndarray
    air_c: np.ndarray
    direction: np.ndarray


def _ramp_to(here_c: float, target_c: float, rate_c_per_s: float) -> np.ndarray:
    """One leg's air on the 1-s grid after ``here_c``, ending at ``target_c``."""
    n = max(int(np.ceil(abs(target_c - here_c) / rate_c_per_s)), 1)
    return here_c + (target_c - here_c) * np.arange(1, n + 1) / n


def air_program(spec: RampSpec) -> np.ndarray:
    """Chamber air (°C) on a 1-s grid at the ramp rate: ``lab``: start → peak → end, no hold;
    ``plan``: safe → low → high → safe with the turnaround holds (module docstring)."""
    r = spec.rate_c_per_min / 60.0
    if spec.program == "lab":
        parts = [np.array([spec.start_c])]
        for a, b in [(spec.start_c, spec.peak_c), (spec.peak_c, spec.end_c)]:
            parts.append(_ramp_to(a, b, r))
        return np.concatenate(parts)
    if spec.program != "plan":
        raise ValueError(f"program {spec.program!r}: 'lab' or 'plan'")
    a = np.exp(-1.0 / spec.die_tau_s)
    # the plan's hold cap and shortest hold in s (three blocks of half a sweep, at least 4)
    n_pos = len(spec.positions) if spec.positions is not None else 24
    step_s = pr.MOVE_S + spec.n_samples / pr.FS_HZ
    min_hold_s = int(np.ceil(spec.min_hold_blocks * max(4, n_pos // 2) * step_s))
    max_hold_s = int(spec.max_hold_min * 60)
    air = [spec.safe_c]
    die = spec.safe_c
    targets = [spec.low_c, spec.high_c, spec.safe_c]
    for i, target in enumerate(targets):
        leg = _ramp_to(air[-1], target, r)
        for x in leg:  # the die as die_lag steps it, to know when a hold may end
            die = air[-1] + (die - air[-1]) * a
            air.append(float(x))
        turning = i + 1 < len(targets)  # low end after leg 1, high end after leg 2
        if turning:
            held = 0
            while held < max_hold_s and (held < min_hold_s
                                         or abs(die - target) > spec.edge_gap_c):
                die = air[-1] + (die - air[-1]) * a
                air.append(float(target))
                held += 1
    return np.asarray(air)


def hold_minutes(spec: RampSpec) -> list[float]:
    """The plan's turnaround holds (min): runs of the air standing at the low and high end."""
    if spec.program != "plan":
        return []
    air = air_program(spec)
    out = []
    for end in (spec.low_c, spec.high_c):
        at = np.flatnonzero(air == end)
        out.append((at.size - 1) / 60.0 if at.size else 0.0)
    return out


def die_lag(air_c: np.ndarray, tau_s: float) -> np.ndarray:
    """gen2's die: first-order lag behind the air, the exact exponential step per second
    (as :func:`benchmarks.blind.gen2.simulate.scene`), settled at the first air value."""
    a = np.exp(-1.0 / tau_s)
    die = np.empty_like(air_c)
    die[0] = air_c[0]
    for i in range(1, air_c.size):
        die[i] = air_c[i - 1] + (die[i - 1] - air_c[i - 1]) * a
    return die


def ramp_record(spec: RampSpec, sensor: Sensor2, pools: NoisePools, seed: int
                ) -> tuple[dict[str, np.ndarray], RampTruth]:
    """The ramp recording's columns (capture means) and its truth per row."""
    rng = np.random.default_rng(seed)
    air = air_program(spec)
    die = die_lag(air, spec.die_tau_s)
    betas, alphas = pr.SCHEDULES_DEG[spec.schedule]  # as Protocol2.angles_deg
    ang_all = np.deg2rad(np.array([(a, b) for b in betas for a in alphas], float))
    ang = ang_all if spec.positions is None else ang_all[list(spec.positions)]
    n = spec.n_samples
    cap_s = n / pr.FS_HZ
    step_s = pr.MOVE_S + cap_s
    t_mid = np.arange(pr.MOVE_S + cap_s / 2, air.size - 2 - cap_s, step_s)
    pos = np.arange(t_mid.size) % len(ang)
    # Per-capture means of the die and air over the capture window (1-s grid).
    lo = np.floor(t_mid - cap_s / 2).astype(int)
    hi = np.maximum(np.ceil(t_mid + cap_s / 2).astype(int), lo + 1)
    csum_d, csum_a = np.concatenate([[0], np.cumsum(die)]), np.concatenate([[0], np.cumsum(air)])
    die_c = (csum_d[hi + 1] - csum_d[lo]) / (hi + 1 - lo)
    air_c = (csum_a[hi + 1] - csum_a[lo]) / (hi + 1 - lo)
    idx = np.clip(np.round(t_mid).astype(int), 1, air.size - 2)
    die_rate = (die[idx + 1] - die[idx - 1]) / 2.0 * 60.0
    direction = np.sign(air[idx + 1] - air[idx - 1])
    # the air standing (a plan's hold): the last direction it moved in (heating if none)
    moved = np.flatnonzero(direction != 0)
    if moved.size:
        last = np.maximum.accumulate(np.where(direction != 0, np.arange(direction.size), -1))
        direction = np.where(last >= 0, direction[np.maximum(last, 0)], 1.0)
    direction[direction == 0] = 1.0
    e_z = np.array([0.0, 0.0, 1.0])
    ref = np.array([pr.force_in_sensor(a, b, e_z) for a, b in ang[pos]])
    # Each visit re-seats the sensor: a small rotation of the true force (gen2's shape).
    tilt = rng.choice(pools.placement, (t_mid.size, 3)) * sim.PLACEMENT_RAD
    force = ref + np.cross(tilt, ref)
    pat = fx.pattern(rng, 2, t_mid.size)
    state = {"force_g": force, "direction": direction, "die_rate_c_per_min": die_rate}
    mean_true = sensor.output_g(force, die_c)
    if spec.rate_ug_per_c_per_min:
        mean_true += fx.output_offset_g("temperature_rate", spec.rate_ug_per_c_per_min, pat,
                                        state)
    if spec.hysteresis_ug:
        pat_h = fx.pattern(rng, 2, t_mid.size)
        mean_true += fx.output_offset_g("thermal_hysteresis", spec.hysteresis_ug, pat_h, state)
    means = np.empty_like(mean_true)
    sds = np.empty_like(mean_true)
    for i in range(t_mid.size):
        x = (mean_true[i] + spec.sensor_noise_g * pools.block(rng, "sensor", n)
             + spec.vib_sd_g * pools.block(rng, "vibration", n))
        x = np.round(x / sim.LSB_G) * sim.LSB_G
        means[i], sds[i] = x.mean(0), x.std(0, ddof=1)
    cols: dict[str, np.ndarray] = {
        "t_s": np.round(t_mid, 1), "position": pos.astype(float),
        "ref_x": ref[:, 0], "ref_y": ref[:, 1], "ref_z": ref[:, 2],
        "ax": means[:, 0], "ay": means[:, 1], "az": means[:, 2],
        "n": np.full(t_mid.size, n, float),
        "sd_x": sds[:, 0], "sd_y": sds[:, 1], "sd_z": sds[:, 2]}
    for name in spec.columns:
        val, lsb, sd = ((die_c, sim.SENSOR_CH_LSB_C, sim.SENSOR_CH_SD_C) if name == "sensor_c"
                        else (air_c, sim.CHAMBER_LSB_C, sim.CHAMBER_SD_C))
        draws = val[:, None] + sd * rng.standard_normal((val.size, n))
        cols[name] = np.round(np.mean(np.round(draws / lsb) * lsb, axis=1), 3)
    return cols, RampTruth(die_c, die_rate, air_c, direction)


def static_readings(sensor: Sensor2, pools: NoisePools, refs_g: np.ndarray,
                    die_c: np.ndarray, seed: int, n_samples: int = 100,
                    sensor_noise_g: float = 80e-6, vib_sd_g: float = 0.3e-3) -> np.ndarray:
    """Fresh static capture means (N,3) at rest (die = air, no rate, no re-seat bias):
    the held-out readings, with the ramp's own noise and ADXL355 code."""
    rng = np.random.default_rng(seed)
    mean_true = sensor.output_g(refs_g, die_c)
    out = np.empty_like(mean_true)
    for i in range(len(refs_g)):
        x = (mean_true[i] + sensor_noise_g * pools.block(rng, "sensor", n_samples)
             + vib_sd_g * pools.block(rng, "vibration", n_samples))
        out[i] = (np.round(x / sim.LSB_G) * sim.LSB_G).mean(0)
    return out


def true_force_g(sensor: Sensor2, raw_g: np.ndarray, die_c: np.ndarray) -> np.ndarray:
    """The oracle: the true gen2 sensor inverted at the true die temperature."""
    return np.linalg.solve(sensor.gain(die_c), (raw_g - sensor.bias_g(die_c))[..., None])[..., 0]
