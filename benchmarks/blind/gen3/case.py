"""One seeded gen3 null (issue 22): draw sensor, thermal chain, noise and protocol, lay out
the campaign's times, and produce the recording's rows (one per capture)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
from typing import Protocol as Hook

import numpy as np

from benchmarks.blind.gen3.noise import NoiseSpec, capture, draw_noise
from benchmarks.blind.gen3.protocol import Protocol, draw_protocol, pass_order
from benchmarks.blind.gen3.schedules import small_rotation
from benchmarks.blind.gen3.sensor import GainBiasSensor, draw_sensor
from benchmarks.blind.gen3.thermal import (
    START_C,
    ThermalSpec,
    air_profile,
    chamber_reading,
    channel_reading,
    draw_thermal,
    settle_s,
)

P_HEAVY, P_VIBRATION, P_QUANTISED = 0.35, 0.35, 0.4


@dataclass(frozen=True)
class Case:
    seed: int
    sensor: GainBiasSensor
    thermal: ThermalSpec
    noise: NoiseSpec
    protocol: Protocol

    def features(self) -> dict[str, Any]:
        """What the report breaks the false alarms down by."""
        p, nz, th = self.protocol, self.noise, self.thermal
        return {
            "schedule": p.schedule_name, "positions": len(p.directions),
            "plateaus": len(p.setpoints_c), "order": p.order, "visits": p.visits,
            "shuffled": p.shuffled, "fixture": p.fixture,
            "place_max_mrad": round(p.place_max_rad * 1e3, 3),
            "n": nz.n, "odr_hz": nz.odr_hz,
            "heavy_nu": None if nz.nu is None else round(nz.nu, 2),
            "vibration_rms_mg": None if nz.vibration is None
            else round(nz.vibration.rms_g * 1e3, 3),
            "raw_lsb_ug": None if nz.raw_lsb_g is None else round(nz.raw_lsb_g * 1e6, 1),
            "t_lsb_c": th.channel_lsb_c, "t_noise_c": round(th.channel_noise_c, 3),
            "t_dither": round(th.channel_noise_c / th.channel_lsb_c, 3),
            "tau_die_min": round(th.tau_die_s / 60.0, 1),
        }


def draw_case(seed: int) -> Case:
    rng = np.random.default_rng(seed)
    heavy, vib, quant = (bool(rng.uniform() < p) for p in (P_HEAVY, P_VIBRATION, P_QUANTISED))
    return Case(seed=seed, sensor=draw_sensor(rng), thermal=draw_thermal(rng),
                noise=draw_noise(rng, heavy=heavy, vibration=vib, quantised=quant),
                protocol=draw_protocol(rng))


@dataclass
class Slot:
    """One capture laid out in time: its window start, step and position."""

    start_s: float
    step: int
    setpoint_c: float
    position: int


@dataclass
class Layout:
    slots: list[Slot] = field(default_factory=list)
    holds: list[tuple[float, float, float]] = field(default_factory=list)


def layout(rng: np.random.Generator, case: Case) -> Layout:
    """Ramp to each setpoint, soak until the step is far below the noise, then the passes
    (move ±20 %, 2–5 s to settle, the capture window)."""
    p, th, nz = case.protocol, case.thermal, case.noise
    sigma_mean = float(np.min(nz.sample_sigma_g)) / np.sqrt(nz.n)
    slope = case.sensor.slope_g_per_c()
    out, t, prev = Layout(), 0.0, START_C
    for k, sp in enumerate(p.setpoints_c):
        hold_start = t + abs(sp - prev) / th.ramp_c_per_min * 60.0 + 60.0
        cursor = hold_start + settle_s(th, sp - prev, slope, sigma_mean)
        for _ in range(p.visits):
            for pos in pass_order(rng, p):
                cursor += p.move_s * rng.uniform(0.8, 1.2) + rng.uniform(2.0, 5.0)
                out.slots.append(Slot(start_s=cursor, step=k, setpoint_c=sp, position=int(pos)))
                cursor += nz.window_s
        t = cursor + 30.0
        out.holds.append((hold_start, t, sp))
        prev = sp
    return out


ROW_COLUMNS = ("t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position",
               "ref_x", "ref_y", "ref_z", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z")


class EffectHook(Hook):
    """What an effect adds (``gen3.effects``): to the output before the raw samples are
    drawn (g) and to the die temperature the channel reads (°C), capture by capture. It
    draws nothing from the case's generator, so the noise is the null's draw for draw."""

    def extra_g(self, i: int, force: np.ndarray, die_c: float,
                vib_var: np.ndarray) -> np.ndarray: ...

    def channel_c(self, i: int) -> float: ...


def vibration_variance(nz: NoiseSpec, level: float) -> np.ndarray:
    """The vibration's variance per axis (g²) at a plateau's level: the common sinusoid's
    share along its direction plus the per-axis one (``noise.vibration_samples``)."""
    if nz.vibration is None:
        return np.zeros(3)
    v = nz.vibration
    return (v.rms_g * level) ** 2 * (v.common_share * v.direction**2 + 1.0 - v.common_share)


def simulate(case: Case, effect: EffectHook | None = None) -> list[dict[str, Any]]:
    """The recording's rows, in time order (``err_g``: the drawn error, not written;
    ``die_c``, ``vib_var``, ``extra_g``: the die temperature, the vibration's variance per
    axis and what ``effect`` added, not written either)."""
    rng = np.random.default_rng([case.seed, 1])
    lay = layout(rng, case)
    prof = air_profile(case.thermal, lay.holds, phase=float(rng.uniform(0, 2 * np.pi)))
    nz, p = case.noise, case.protocol
    levels = rng.uniform(0.3, 1.0, len(p.setpoints_c))  # vibration per plateau
    sample_dt = np.arange(nz.n) / nz.odr_hz
    rows = []
    for i, slot in enumerate(lay.slots):
        die = prof.die_at(slot.start_s + sample_dt)
        ref = p.directions[slot.position]
        force = ref
        if p.place_max_rad > 0.0:
            force = small_rotation(rng, p.place_max_rad) @ ref
        true_g = case.sensor.output_g(force, float(die.mean()))
        vib_var = vibration_variance(nz, float(levels[slot.step]))
        extra = np.zeros(3) if effect is None else effect.extra_g(
            i, force, float(die.mean()), vib_var)
        mean, sd = capture(rng, nz, true_g + extra, float(levels[slot.step]))
        mid = slot.start_s + nz.window_s / 2.0
        sensor_c = channel_reading(
            rng, case.thermal, die if effect is None else die + effect.channel_c(i))
        t_err_c = sensor_c - case.thermal.channel_offset_c - float(die.mean())
        rows.append({
            "t_s": mid, "step": slot.step, "setpoint_c": slot.setpoint_c,
            "chamber_c": chamber_reading(rng, case.thermal, float(prof.air_at(np.array(mid)))),
            "sensor_c": sensor_c, "position": slot.position,
            "ref_x": ref[0], "ref_y": ref[1], "ref_z": ref[2],
            "ax": mean[0], "ay": mean[1], "az": mean[2], "n": nz.n,
            "sd_x": sd[0], "sd_y": sd[1], "sd_z": sd[2],
            "err_g": mean - extra - case.sensor.output_g(ref, float(die.mean())),
            "die_c": float(die.mean()), "vib_var": vib_var, "extra_g": extra,
            "t_err_g": case.sensor.output_g(ref, float(die.mean()) + t_err_c)
            - case.sensor.output_g(ref, float(die.mean()))})
    return rows


def drawn_error_ug(rows: list[dict[str, float]]) -> float:
    """RMS over rows and axes of the error drawn into the means (noise, vibration,
    quantisation, re-seating), against the sensor at its nominal pose and die temperature:
    what a fit of the right model should leave (µg)."""
    err = np.array([r["err_g"] for r in rows])
    return float(np.sqrt(np.mean(err**2)) * 1e6)


def drawn_along_ug(rows: list[dict[str, Any]]) -> float:
    """RMS of the drawn error along each row's reference (µg): what |a| − g sees, the
    measure of ``calibrate``'s Eq. 9 RMSE (a re-seating turn moves gravity across it)."""
    err = np.array([r["err_g"] for r in rows])
    ref = np.array([[r["ref_x"], r["ref_y"], r["ref_z"]] for r in rows])
    return float(np.sqrt(np.mean(np.sum(err * ref, axis=1) ** 2)) * 1e6)


def channel_error_ug(rows: list[dict[str, Any]]) -> float:
    """RMS over plateaus and axes of the plateau's mean output error that the temperature
    channel's own error (noise averaged, rounding not dithered away) implies, read at the
    recorded temperature (µg): the part of the temperature channel a per-reading model
    cannot see as noise."""
    steps = np.array([r["step"] for r in rows])
    err = np.array([r["t_err_g"] for r in rows])
    means = np.array([err[steps == k].mean(axis=0) for k in np.unique(steps)])
    return float(np.sqrt(np.mean(means**2)) * 1e6)


def stated_noise_ug(rows: list[dict[str, float]]) -> float:
    """RMS over rows and axes of sd/√n: the noise the recording itself states (µg)."""
    sd = np.array([[r["sd_x"], r["sd_y"], r["sd_z"]] for r in rows])
    n = np.array([r["n"] for r in rows])[:, None]
    return float(np.sqrt(np.mean(sd**2 / n)) * 1e6)
