"""Air, die and the two temperature channels for gen3 (issue 22).

The chamber air ramps between setpoints and holds each with a small controller ripple; the
die follows the air through one first-order lag (time constant τ); the sensor's channel
reads the die with a constant offset, white noise and a quantiser, averaged over the
capture's samples; ``chamber_c`` is the controller's reading of the air. Captures start
only once the step has decayed far below the noise (``settle_s``), so a null carries no lag.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

GRID_S = 1.0  # the air/die time grid
START_C = 20.0  # the chamber starts at room temperature


@dataclass(frozen=True)
class ThermalSpec:
    ramp_c_per_min: float
    tau_die_s: float
    ripple_c: float  # controller ripple amplitude of the air while holding
    ripple_period_s: float
    chamber_noise_c: float
    channel_offset_c: float
    channel_noise_c: float  # per raw temperature sample
    channel_lsb_c: float


CHANNEL_LSBS_C = (0.01, 0.0625, 0.11, 0.25, 0.5)


def draw_thermal(rng: np.random.Generator) -> ThermalSpec:
    """Ramps 0.5–3 °C/min, die τ 3–15 min, ripple ≤ 0.1 °C, channel offset ±3 °C, channel
    noise 0.01–0.2 °C per sample, LSB 0.01–0.5 °C."""
    return ThermalSpec(
        ramp_c_per_min=float(rng.uniform(0.5, 3.0)),
        tau_die_s=float(rng.uniform(180.0, 900.0)),
        ripple_c=float(rng.uniform(0.0, 0.1)),
        ripple_period_s=float(rng.uniform(300.0, 1200.0)),
        chamber_noise_c=float(rng.uniform(0.005, 0.05)),
        channel_offset_c=float(rng.uniform(-3.0, 3.0)),
        channel_noise_c=float(rng.uniform(0.01, 0.2)),
        channel_lsb_c=float(rng.choice(CHANNEL_LSBS_C)),
    )


def settle_s(spec: ThermalSpec, step_c: float, slope_g_per_c: float, sigma_g: float) -> float:
    """Soak time after the air reaches its setpoint so that what is left of the step in the
    output (|step|·slope·e^(−t/τ)) is below 1 % of the capture noise; at least 30 min."""
    left_g = max(abs(step_c), 1.0) * max(slope_g_per_c, 1e-6)
    need = spec.tau_die_s * np.log(max(left_g / (0.01 * sigma_g), 1.0))
    return float(max(need, 1800.0))


@dataclass
class AirProfile:
    """Air temperature on a regular grid; holds are (start_s, end_s, setpoint_c)."""

    t_s: np.ndarray
    air_c: np.ndarray
    die_c: np.ndarray

    def die_at(self, t_s: np.ndarray) -> np.ndarray:
        return np.interp(t_s, self.t_s, self.die_c)

    def air_at(self, t_s: np.ndarray) -> np.ndarray:
        return np.interp(t_s, self.t_s, self.air_c)


def air_profile(spec: ThermalSpec, holds: list[tuple[float, float, float]],
                phase: float) -> AirProfile:
    """Piecewise-linear air through the holds' (start, end, setpoint), ramps between them
    at the spec's rate, ripple while holding; die by the exact first-order lag."""
    end = holds[-1][1] + 60.0
    t = np.arange(0.0, end + GRID_S, GRID_S)
    knots_t, knots_c = [0.0], [START_C]
    for start, stop, sp in holds:
        knots_t += [start, stop]
        knots_c += [sp, sp]
    air = np.interp(t, knots_t, knots_c)
    holding = np.zeros_like(t, dtype=bool)
    for start, stop, _ in holds:
        holding |= (t >= start) & (t <= stop)
    ripple = spec.ripple_c * np.sin(2 * np.pi * t / spec.ripple_period_s + phase)
    air = air + np.where(holding, ripple, 0.0)
    a = np.exp(-GRID_S / spec.tau_die_s)
    die, _ = lfilter([1.0 - a], [1.0, -a], air, zi=[a * START_C])
    return AirProfile(t_s=t, air_c=air, die_c=die)


def channel_reading(rng: np.random.Generator, spec: ThermalSpec, die_c: np.ndarray) -> float:
    """The capture's ``sensor_c``: the mean of the quantised raw channel samples."""
    raw = die_c + spec.channel_offset_c + spec.channel_noise_c * rng.standard_normal(die_c.size)
    return float(np.mean(np.round(raw / spec.channel_lsb_c) * spec.channel_lsb_c))


def chamber_reading(rng: np.random.Generator, spec: ThermalSpec, air_c: float) -> float:
    """The controller's ``chamber_c`` (0.01 °C resolution)."""
    return float(np.round(air_c + spec.chamber_noise_c * rng.standard_normal(), 2))
