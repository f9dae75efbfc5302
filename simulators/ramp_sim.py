"""Ramp-method recordings from the twin's physics (tests, benchmarks, later the engine).

The seed's second temperature method (Sec. 1): the chamber ramps through the range
while the table sweeps the 24 positions of Table 1 over and over; every capture is
stamped with each sensor's own die temperature (``sensor_c``) and the chamber air
(``chamber_c``). No plateau anywhere, unless ``edge_hold_min`` holds the chamber at
the start and the peak (a *mixed* recording: soaks at the edges, ramps between).

Physics (one rig, several sensors on it):

* working setpoint: piecewise linear at ``rate_c_per_min`` (start → peak → end), with
  optional holds at start and peak; before the recording the rig stood at the start
  long enough for air and dies to settle;
* air behind the working setpoint and each die behind the air: first-order lags of
  :mod:`calibration.thermal_plant` (``lag_series``), each sensor its own ``die_tau_s``;
* the output: :class:`simulators.truth.SensorTruth` (Eq. 1 with cubic parameters of the
  die temperature, Eq. 8) plus its effects (``temperature_rate`` on the die's rate over
  the capture, ``thermal_hysteresis`` with the die's own last excursion: +1 heating, −1
  cooling, held while the die stands; −1 before the first, the rig having cooled to the start);
* noise: averaged readings drawn from their sampling distribution (σ/√n), sd from a χ
  distribution; the temperature channel reads die + offset + noise/√n, optionally with
  extra per-row noise (``temp_row_noise_c``) and quantised (``temp_lsb_c``, 0.11 °C on
  the bridge).

Imports calibration and simulators only (the engine may reuse it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from calibration.recording import Recording
from calibration.schedules import table1
from calibration.thermal_plant import DEFAULT_AIR_TAU_S, lag_series
from simulators.chamber_sim import DIRECTION_RATE_C_PER_S
from simulators.effects import TemperatureRate, ThermalHysteresis
from simulators.truth import Context, SensorTruth, averaged_readings


@dataclass(frozen=True)
class RampProfile:
    """The chamber's program: start → peak → end at ``rate_c_per_min``, optional edge holds."""

    start_c: float = -40.0
    peak_c: float = 60.0
    end_c: float = 25.0
    rate_c_per_min: float = 1.0
    edge_hold_min: float = 0.0  # hold at start and at peak (captures continue): mixed recording

    def breakpoints(self) -> tuple[np.ndarray, np.ndarray]:
        """(times s, working setpoints °C) of the piecewise-linear program."""
        r = self.rate_c_per_min / 60.0
        hold = self.edge_hold_min * 60.0
        t_up = abs(self.peak_c - self.start_c) / r
        t_down = abs(self.peak_c - self.end_c) / r
        bt = np.cumsum([0.0, hold, t_up, hold, t_down])
        bv = np.array([self.start_c, self.start_c, self.peak_c, self.peak_c, self.end_c])
        return bt, bv

    @property
    def duration_s(self) -> float:
        return float(self.breakpoints()[0][-1])


@dataclass(frozen=True)
class RampRig:
    """Rig timing and noise of the ramp campaign."""

    air_tau_s: float = DEFAULT_AIR_TAU_S
    move_s: float = 12.0  # table slew + settle between positions
    samples_per_position: int = 200
    pv_noise_c: float = 0.02
    dt_s: float = 1.0  # plant integration grid


@dataclass
class RampRun:
    recording: Recording
    die_c: np.ndarray  # true die temperature per row
    air_c: np.ndarray
    truth: SensorTruth
    die_tau_s: float
    extra: dict = field(default_factory=dict)


def simulate_ramp(
    truths: Sequence[SensorTruth],
    die_tau_s: Sequence[float],
    profile: RampProfile = RampProfile(),  # noqa: B008 (frozen)
    rig: RampRig = RampRig(),  # noqa: B008 (frozen)
    seed: int = 0,
    *,
    schedule: np.ndarray | None = None,
    temp_row_noise_c: float = 0.0,
    temp_lsb_c: float = 0.0,
    write_setpoint: bool = False,
) -> list[RampRun]:
    """One ramp campaign of several sensors on one rig: a recording per sensor.

    ``write_setpoint`` adds the working setpoint as ``setpoint_c`` (a ramping column, as
    some loggers write it); by default the recording has no step or setpoint column.
    """
    if len(truths) != len(die_tau_s):
        raise ValueError("one die_tau_s per sensor")
    refs = table1() if schedule is None else np.asarray(schedule, float)
    rng = np.random.default_rng(seed)
    bt, bv = profile.breakpoints()
    grid = np.arange(0.0, bt[-1] + rig.dt_s, rig.dt_s)
    wsp = np.interp(grid, bt, bv)
    air = lag_series(wsp, rig.dt_s, rig.air_tau_s)
    odr = truths[0].odr_hz
    n = int(rig.samples_per_position)
    capture_s = n / odr
    period = rig.move_s + capture_s
    t_mid = np.arange(rig.move_s + capture_s / 2, bt[-1], period)
    n_rows = t_mid.size
    pos = np.arange(n_rows) % refs.shape[0]
    ref = refs[pos]
    air_row = np.interp(t_mid, grid, air)
    runs = []
    for truth, tau in zip(truths, die_tau_s, strict=True):
        die = lag_series(air, rig.dt_s, float(tau))
        die_row = np.interp(t_mid, grid, die)
        rate = (np.interp(t_mid + capture_s / 2, grid, die)
                - np.interp(t_mid - capture_s / 2, grid, die)) / capture_s
        # the die's own last excursion (it, not the air, carries the sensor's history)
        moving = np.where(np.abs(rate) > DIRECTION_RATE_C_PER_S, np.sign(rate), 0.0)
        direction = _direction(moving, start=-1)
        ctx = Context(t_s=t_mid, die_c=die_row, air_c=air_row, die_rate_c_per_s=rate, ref_g=ref,
                      step=np.zeros(n_rows, int), direction=direction,
                      session=np.zeros(n_rows, int), n_samples=np.full(n_rows, float(n)),
                      vib_sd_g=np.zeros(n_rows))
        cols = _readings(truth, ctx, rng, rig.pv_noise_c, temp_row_noise_c, temp_lsb_c)
        cols["position"] = pos.astype(float)
        if write_setpoint:
            cols["setpoint_c"] = np.round(np.interp(t_mid, grid, wsp), 2)
        runs.append(RampRun(Recording.from_columns(cols), die_row, air_row, truth, float(tau),
                            {"context": ctx}))
    return runs


def ramp_twin_sensors(
    count: int,
    seed: int = 0,
    *,
    rate_ug_per_c_per_min: float = 20.0,
    hysteresis_ug: float = 15.0,
    die_tau_s: tuple[float, float] = (300.0, 900.0),
) -> tuple[list[SensorTruth], list[float]]:
    """``count`` ADXL355-class sensors with rate sensitivity and hysteresis, and die lags.

    Sensor i: ``SensorTruth.adxl355_typical(seed + i)``; ``temperature_rate`` gain
    ``rate_ug_per_c_per_min`` × a per-axis pattern (1, −0.6, 0.4) with a random sign;
    ``thermal_hysteresis`` ±``hysteresis_ug`` × (0.5, −1, 0.8); die time constants spread
    evenly over ``die_tau_s``.
    """
    truths, taus = [], []
    for i in range(count):
        t = SensorTruth.adxl355_typical(seed + i)
        sign = 1.0 if (seed + i) % 2 == 0 else -1.0
        k = sign * np.array([1.0, -0.6, 0.4]) * rate_ug_per_c_per_min * 1e-6 * 60.0
        h = np.array([0.5, -1.0, 0.8]) * hysteresis_ug * 1e-6
        t.effects = [TemperatureRate(k_g_per_c_per_s=k), ThermalHysteresis(h_g=h)]
        truths.append(t)
        lo, hi = die_tau_s
        taus.append(lo + (hi - lo) * (i / max(count - 1, 1)))
    return truths, taus


def _direction(sign: np.ndarray, start: int) -> np.ndarray:
    """Last excursion's direction: the sign while moving, the previous one while holding."""
    out = np.empty(sign.size, int)
    last = start
    for i, s in enumerate(sign):
        if s != 0:
            last = int(s)
        out[i] = last
    return out


def _readings(truth: SensorTruth, ctx: Context, rng: np.random.Generator, pv_noise_c: float,
              temp_row_noise_c: float, temp_lsb_c: float) -> dict[str, np.ndarray]:
    """Averaged raw readings and the two temperature columns for the rows of ``ctx``."""
    N = ctx.t_s.size
    mean, sd, sensor_c = averaged_readings(truth, ctx, rng)
    sensor_c = sensor_c + rng.normal(0.0, temp_row_noise_c, N)
    if temp_lsb_c > 0:
        sensor_c = np.round(sensor_c / temp_lsb_c) * temp_lsb_c
    return {
        "t_s": ctx.t_s, "chamber_c": ctx.air_c + rng.normal(0.0, pv_noise_c, N),
        "sensor_c": sensor_c,
        "ref_x": ctx.ref_g[:, 0], "ref_y": ctx.ref_g[:, 1], "ref_z": ctx.ref_g[:, 2],
        "ax": mean[:, 0], "ay": mean[:, 1], "az": mean[:, 2], "n": ctx.n_samples,
        "sd_x": sd[:, 0], "sd_y": sd[:, 1], "sd_z": sd[:, 2],
    }
