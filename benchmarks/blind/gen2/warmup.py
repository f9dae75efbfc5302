"""One-orientation warm-up logs of the second generator (issue 20's independent check).

A board at rest at one orientation while its temperature changes, written as a flight
controller's or IMU module's thermal log: raw samples with a temperature channel. Written
from the physical description of such logs only, on gen2's pieces, none of the project's
twin (``simulators/``) and nothing of ``calibration/``:

* **die temperature** ``T(t)`` follows one of six profiles (:data:`PROFILES`): a heater's
  first-order approach from cold (τ 2–15 min); a board self-heating after power-on (a
  fast die term and a slow board term); rest – heat – rest; heating, then the heater off
  and natural cooling; a PID heater overshooting its setpoint with a limit-cycle ripple;
  a slow chamber ramp that the die follows through its own lag.
* **sensor**: the gravity projection goes through gen2's gain matrix
  (:class:`~benchmarks.blind.gen2.sensor.Sensor2`: scale and coupling errors and their
  thermal change; its own bias terms are replaced), plus a per-axis bias polynomial in
  the die temperature of order 1–3 (0.05–2 mg/°C, curvature), optionally a rate
  sensitivity ``k·dT/dt`` (die rate), a thermal hysteresis (a play operator on the die
  temperature: the offset moves toward ±h as the die heats or cools, over a width
  ``ΔT_h``), and a slow time drift.
* **temperature channel**: the die itself or the die through a first-order lag
  (τ 5–120 s, exact exponential per sample), plus an offset and a little noise, then
  quantised to its LSB (0.0078–0.06 °C, or 1 °C for the channels that print whole
  degrees). It is read once per output sample (not averaged). ``draw_case(seed,
  coarse_dither=True)`` gives the same case with a whole-degree channel whose noise
  before quantisation is 0.1–0.6 LSB (:data:`DITHER_LSB`): a board's MCU sensor or a
  thermistor read to 1 °C that flickers between k and k+1 around each crossing (the
  default draws, and their logs, are unchanged).
* **noise**: white at the sensor's density at the native rate, the acceleration quantised
  to the sensor's LSB at the native rate, then averaged down to the output rate (a
  boxcar decimation, as a logger that averages does); plus a bench disturbance drawn in
  contiguous blocks from the shared real recordings' vibration pool
  (:mod:`~benchmarks.blind.gen2.realnoise`) when pools are given.

:func:`write_log` writes the CSV ``soakcal import --format csv`` reads (a header row
``t_s,ax,ay,az,temp_c``; the acceleration in the case's unit) and a JSON truth file;
:func:`import_args` gives the matching import flags.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import Sensor2, draw_sensor

PROFILES = ("heater", "selfheat", "rest_heat_rest", "heat_cool", "overshoot", "ramp")
G_MS2 = 9.80665
MAX_OUT_HZ = 200.0
# coarse_dither=True: a 1 °C channel with this range of noise before quantisation (LSB)
DITHER_LSB = (0.1, 0.6)
MAX_ROWS = 200_000
CHUNK_ROWS = 20_000  # output rows generated at the native rate at a time (memory)


@dataclass(frozen=True)
class WarmupCase:
    """One log's recipe: every number drawn by :func:`draw_case` (or set by a test)."""

    name: str
    seed: int
    profile: str
    duration_s: float
    start_c: float
    span_c: float  # the die's rise (or the ramp's travel), °C
    tau_s: float  # the profile's main time constant
    native_hz: float
    out_hz: float
    up: tuple[float, float, float]  # unit gravity direction in the sensor frame
    bias_order: int
    bias_ref_c: float
    bias_coef_g: tuple[tuple[float, ...], ...]  # (order+1, 3): Σ c_k·((T − ref)/10 °C)^k
    rate_ug_per_c_per_min: tuple[float, float, float] = (0.0, 0.0, 0.0)
    hysteresis_ug: tuple[float, float, float] = (0.0, 0.0, 0.0)
    hysteresis_width_c: float = 2.0
    drift_ug_per_h: tuple[float, float, float] = (0.0, 0.0, 0.0)
    channel_lag_s: float = 0.0
    channel_lsb_c: float = 0.0  # 0: not quantised
    channel_offset_c: float = 0.0
    channel_noise_c: float = 0.0
    noise_density_ug_rthz: float = 0.0
    accel_lsb_g: float = 0.0
    vib_sd_g: float = 0.0
    accel_unit: str = "g"  # g, mg or m/s2 in the CSV
    kinds: tuple[str, ...] = field(default_factory=tuple)  # labels for grouping results


@dataclass
class WarmupLogData:
    """The samples written (output rate) and their truth."""

    t_s: np.ndarray  # (N,)
    acc_g: np.ndarray  # (N,3) as logged (noise, quantisation, decimation)
    temp_c: np.ndarray  # (N,) the temperature channel as logged
    die_c: np.ndarray  # (N,) the true die temperature
    true_g: np.ndarray  # (N,3) the noiseless output: gravity through the gain + bias path


# --- die temperature --------------------------------------------------------------------
def die_temperature_c(case: WarmupCase, t_s: np.ndarray) -> np.ndarray:
    """The die temperature of the case's profile at times ``t_s`` (closed forms)."""
    t = np.asarray(t_s, float)
    T0, span, tau, dur = case.start_c, case.span_c, case.tau_s, case.duration_s
    if case.profile == "heater":
        return T0 + span * (1.0 - np.exp(-t / tau))
    if case.profile == "selfheat":
        # power-on: the die's own dissipation (τ 40 s, 30 % of the rise) and the board
        # warming slowly around it (τ)
        return T0 + span * (0.3 * (1.0 - np.exp(-t / 40.0)) + 0.7 * (1.0 - np.exp(-t / tau)))
    if case.profile == "rest_heat_rest":
        t_on = 0.25 * dur
        x = np.clip(t - t_on, 0.0, None)
        return T0 + span * (1.0 - np.exp(-x / tau))
    if case.profile == "heat_cool":
        t_off = 0.55 * dur
        hot = T0 + span * (1.0 - np.exp(-t / tau))
        at_off = T0 + span * (1.0 - np.exp(-t_off / tau))
        cool = T0 + (at_off - T0) * np.exp(-(t - t_off) / (1.5 * tau))
        return np.where(t <= t_off, hot, cool)
    if case.profile == "overshoot":
        # an under-damped closed loop (ζ 0.35) toward T0 + span, then a limit-cycle ripple
        # of the heater's on/off duty (±1.5 % of the span, period τ/3)
        zeta, wn = 0.35, 1.0 / tau * 2.5
        wd = wn * np.sqrt(1.0 - zeta**2)
        step = 1.0 - np.exp(-zeta * wn * t) * (np.cos(wd * t)
                                                + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t))
        ripple = 0.015 * span * np.sin(2 * np.pi * t / (tau / 3.0)) * (1.0 - np.exp(-t / tau))
        return T0 + span * step + ripple
    if case.profile == "ramp":
        # chamber air ramps linearly over the log's first 80 %, then holds; the die
        # follows through a first-order lag τ (exact solution of dT/dt = (air − T)/τ)
        r = span / (0.8 * dur)
        t1 = 0.8 * dur
        tt = np.minimum(t, t1)
        during = T0 + r * (tt - tau * (1.0 - np.exp(-tt / tau)))
        at_t1 = T0 + r * (t1 - tau * (1.0 - np.exp(-t1 / tau)))
        after = T0 + span + (at_t1 - T0 - span) * np.exp(-(t - t1) / tau)
        return np.where(t <= t1, during, after)
    raise ValueError(f"unknown profile {case.profile!r}")


def first_order_lag(x: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    """y' = (x − y)/τ with x held over each sample step (exact per step), y(0) = x(0)."""
    if tau_s <= 0:
        return np.asarray(x, float).copy()
    a = float(np.exp(-dt_s / tau_s))
    y = np.empty(len(x))
    y[0] = x[0]
    # recursive filter: y[n] = a·y[n−1] + (1 − a)·x[n]
    from scipy.signal import lfilter
    y[1:] = lfilter([1.0 - a], [1.0, -a], x[1:], zi=[a * x[0]])[0]
    return y


def play_hysteresis(die_c: np.ndarray, width_c: float) -> np.ndarray:
    """A unit hysteresis state in [−1, 1] driven by the die temperature: it moves toward
    +1 while heating and −1 while cooling, by dT/width per step (a saturating play
    operator: the offset depends on where the die has been, not on its rate)."""
    s = np.empty(len(die_c))
    state = 0.0
    d = np.diff(die_c, prepend=die_c[0])
    for i, di in enumerate(d):
        state += (np.sign(di) - state) * min(abs(di) / width_c, 1.0)
        s[i] = state
    return s


# --- the sensor -------------------------------------------------------------------------
def bias_g(case: WarmupCase, die_c: np.ndarray) -> np.ndarray:
    """(N,3) the per-axis bias polynomial in the die temperature."""
    x = (np.asarray(die_c, float) - case.bias_ref_c) / 10.0
    c = np.asarray(case.bias_coef_g)
    return np.vander(x, c.shape[0], increasing=True) @ c


def true_output_g(case: WarmupCase, sensor: Sensor2, t_s: np.ndarray) -> tuple[np.ndarray,
                                                                               np.ndarray]:
    """(die °C (N,), noiseless output (N,3) g) at times ``t_s``: gravity through gen2's gain
    at the die temperature, the bias polynomial, the rate, hysteresis and drift terms."""
    die = die_temperature_c(case, t_s)
    up = np.tile(np.asarray(case.up, float), (len(t_s), 1))
    out = np.einsum("nij,nj->ni", sensor.gain(die), up) + bias_g(case, die)
    if any(case.rate_ug_per_c_per_min):
        rate_c_per_min = np.gradient(die, t_s) * 60.0
        out += rate_c_per_min[:, None] * np.asarray(case.rate_ug_per_c_per_min) * 1e-6
    if any(case.hysteresis_ug):
        out += (play_hysteresis(die, case.hysteresis_width_c)[:, None]
                * np.asarray(case.hysteresis_ug) * 1e-6)
    if any(case.drift_ug_per_h):
        out += (t_s / 3600.0)[:, None] * np.asarray(case.drift_ug_per_h) * 1e-6
    return die, out


def gain_only_sensor(sensor: Sensor2) -> Sensor2:
    """gen2's sensor with its bias terms removed (the case's polynomial replaces them)."""
    return Sensor2(sensor.g0, sensor.g1, sensor.g2, np.zeros_like(sensor.bias_cheb_g))


# --- the log ------------------------------------------------------------------------------
def simulate(case: WarmupCase, pools: NoisePools | None = None,
             noise_seed: int | None = None) -> WarmupLogData:
    """The log's output-rate samples: white noise and the acceleration LSB applied at the
    native rate and boxcar-averaged to ``out_hz``; the channel read once per output
    sample; the bench disturbance (when ``pools``) added at the output rate.

    ``noise_seed``: the noise's own seed (default ``case.seed``); the sensor is always
    drawn from ``case.seed + 1``, so another noise seed is the same sensor's other log."""
    rng = np.random.default_rng(case.seed if noise_seed is None else noise_seed)
    sensor = gain_only_sensor(draw_sensor(np.random.default_rng(case.seed + 1)))
    k = int(round(case.native_hz / case.out_hz))
    n = int(case.duration_s * case.out_hz)
    t = np.arange(n) / case.out_hz
    die, true = true_output_g(case, sensor, t)
    acc = np.empty_like(true)
    sd_native = case.noise_density_ug_rthz * 1e-6 * np.sqrt(case.native_hz / 2.0)
    for a in range(0, n, CHUNK_ROWS):
        b = min(n, a + CHUNK_ROWS)
        x = np.repeat(true[a:b], k, axis=0)
        if sd_native > 0:
            x = x + rng.normal(0.0, sd_native, x.shape)
        if case.accel_lsb_g > 0:
            x = np.round(x / case.accel_lsb_g) * case.accel_lsb_g
        acc[a:b] = x.reshape(b - a, k, 3).mean(axis=1)
    if pools is not None and case.vib_sd_g > 0:
        acc += case.vib_sd_g * _pool_series(rng, pools, n)
    chan = first_order_lag(die, 1.0 / case.out_hz, case.channel_lag_s)
    chan = chan + case.channel_offset_c + rng.normal(0.0, case.channel_noise_c, n)
    if case.channel_lsb_c > 0:
        chan = np.round(chan / case.channel_lsb_c) * case.channel_lsb_c
    return WarmupLogData(t, acc, chan, die, true)


def _pool_series(rng: np.random.Generator, pools: NoisePools, n: int) -> np.ndarray:
    """n samples of the vibration pool, as contiguous blocks of at most half the pool."""
    m = len(pools.vibration) // 2
    parts, have = [], 0
    while have < n:
        take = min(m, n - have)
        parts.append(pools.block(rng, "vibration", take))
        have += take
    return np.vstack(parts)


UNIT_SCALE = {"g": 1.0, "mg": 1e3, "m/s2": G_MS2}


def write_log(case: WarmupCase, data: WarmupLogData, folder: Path) -> tuple[Path, Path]:
    """``folder/NAME.csv`` (``t_s,ax,ay,az,temp_c``, acceleration in ``case.accel_unit``)
    and ``folder/NAME.truth.json`` (the case and the sensor's gain terms)."""
    folder.mkdir(parents=True, exist_ok=True)
    csv_path, truth_path = folder / f"{case.name}.csv", folder / f"{case.name}.truth.json"
    a = data.acc_g * UNIT_SCALE[case.accel_unit]
    np.savetxt(csv_path, np.column_stack([data.t_s, a, data.temp_c]), delimiter=",",
               fmt=["%.5f", "%.9g", "%.9g", "%.9g", "%.8g"], header="t_s,ax,ay,az,temp_c",
               comments="")
    sensor = gain_only_sensor(draw_sensor(np.random.default_rng(case.seed + 1)))
    truth = {"case": asdict(case), "gain_g0": sensor.g0.tolist(), "gain_g1": sensor.g1.tolist(),
             "gain_g2": sensor.g2.tolist(),
             "die_c_span": [float(data.die_c.min()), float(data.die_c.max())],
             "true_change_mg": (np.ptp(data.true_g, axis=0) * 1e3).tolist()}
    truth_path.write_text(json.dumps(truth, indent=1))
    return csv_path, truth_path


def import_args(case: WarmupCase) -> list[str]:
    """``soakcal import --format csv`` flags for :func:`write_log`'s file."""
    return ["--accel-unit", case.accel_unit, "--columns", "t=t_s,ax=ax,ay=ay,az=az,temp=temp_c"]


# --- drawing cases ---------------------------------------------------------------------------
SENSOR_CLASSES = {
    # name: (noise density µg/√Hz, acceleration LSB g)
    "adxl355": (25.0, 3.9e-6),
    "bmi088": (160.0, 1 / 1365.0),  # ±24 g range: 0.73 mg
    "icm42688": (70.0, 1 / 2048.0),  # ±16 g: 0.49 mg
    "bmi270": (160.0, 1 / 4096.0),  # ±8 g: 0.24 mg
    "lsm6dso": (70.0, 0.061e-3),  # ±2 g
}


def draw_case(seed: int, coarse_dither: bool = False) -> WarmupCase:
    """A random case spanning what real one-orientation thermal logs look like.

    ``coarse_dither``: the same case (every other draw as without it) with a 1 °C channel
    whose noise before quantisation is drawn from :data:`DITHER_LSB` (a second generator
    seeded from ``seed``, so the main draws are untouched); its kinds say ``quant1C`` and
    ``dither``."""
    case = _draw_case(seed)
    if not coarse_dither:
        return case
    noise_lsb = float(np.random.default_rng([seed, 20]).uniform(*DITHER_LSB))
    kinds = tuple(k for k in case.kinds if k not in ("quant", "quant1C"))
    return replace(case, name=f"w{seed:04d}d", channel_lsb_c=1.0, channel_noise_c=noise_lsb,
                   kinds=(*kinds, "quant1C", "dither"))


def _draw_case(seed: int) -> WarmupCase:
    rng = np.random.default_rng(seed)
    kinds: list[str] = []
    profile = PROFILES[int(rng.integers(len(PROFILES)))]
    kinds.append(profile)
    duration_s = float(np.round(rng.uniform(3.0, 60.0) * 60.0))
    if duration_s < 600:
        kinds.append("short")
    span_c = float(rng.uniform(3.0, 40.0))
    tau_s = float(rng.uniform(2.0, 15.0) * 60.0)
    if profile == "ramp":
        tau_s = float(rng.uniform(60.0, 300.0))  # the die's lag behind the chamber air
    start_c = float(rng.uniform(-20.0, 30.0))
    native_hz = float(rng.choice([50.0, 100.0, 200.0, 400.0, 500.0, 1000.0]))
    out_hz = next(f for f in (native_hz, 200.0, 100.0, 50.0, 25.0, 20.0, 10.0)
                  if f <= MAX_OUT_HZ and f * duration_s <= MAX_ROWS
                  and (native_hz / f).is_integer())
    up = rng.normal(size=3)
    if rng.uniform() < 0.5:  # half the boards lie flat: one axis near ±1 g
        up = np.zeros(3)
        up[int(rng.integers(3))] = rng.choice([-1.0, 1.0])
        up += rng.normal(0.0, 0.02, 3)
    up = up / np.linalg.norm(up)
    order = int(rng.integers(1, 4))
    slope = rng.uniform(0.05, 2.0, 3) * rng.choice([-1.0, 1.0], 3) * 1e-3 * 10.0  # g/10 °C
    coef = np.zeros((order + 1, 3))
    coef[0] = rng.uniform(-0.05, 0.05, 3)
    coef[1] = slope
    for j in range(2, order + 1):  # curvature: up to 30 % (quadratic), 10 % (cubic) of slope
        coef[j] = slope * rng.uniform(-1.0, 1.0, 3) * (0.3 if j == 2 else 0.1)
    bias_ref_c = start_c + 0.5 * span_c
    sensor_name = str(rng.choice(list(SENSOR_CLASSES)))
    density, lsb = SENSOR_CLASSES[sensor_name]
    kinds.append(sensor_name)
    rate = (0.0, 0.0, 0.0)
    if rng.uniform() < 0.35:
        rate = tuple((rng.uniform(10.0, 80.0, 3) * rng.choice([-1.0, 1.0], 3)).tolist())
        kinds.append("rate")
    hyst = (0.0, 0.0, 0.0)
    if rng.uniform() < 0.2:
        hyst = tuple((rng.uniform(20.0, 200.0, 3) * rng.choice([-1.0, 1.0], 3)).tolist())
        kinds.append("hysteresis")
    drift = (0.0, 0.0, 0.0)
    if rng.uniform() < 0.3:
        drift = tuple((rng.uniform(5.0, 100.0, 3) * rng.choice([-1.0, 1.0], 3)).tolist())
        kinds.append("drift")
    lag = 0.0
    if rng.uniform() < 0.5:
        lag = float(np.exp(rng.uniform(np.log(5.0), np.log(120.0))))
        kinds.append("lag")
    r = rng.uniform()
    if r < 0.15:
        chan_lsb = 1.0
        kinds.append("quant1C")
    else:
        chan_lsb = float(rng.choice([0.0078125, 0.015625, 0.03125, 0.06]))
        if chan_lsb >= 0.03:
            kinds.append("quant")
    vib = float(rng.choice([0.0, 0.0, rng.uniform(0.05, 0.5) * 1e-3]))
    if vib > 0:
        kinds.append("vibration")
    return WarmupCase(
        name=f"w{seed:04d}", seed=seed, profile=profile, duration_s=duration_s,
        start_c=start_c, span_c=span_c, tau_s=tau_s, native_hz=native_hz, out_hz=out_hz,
        up=tuple(up.tolist()), bias_order=order, bias_ref_c=bias_ref_c,
        bias_coef_g=tuple(tuple(r_.tolist()) for r_ in coef),
        rate_ug_per_c_per_min=rate, hysteresis_ug=hyst,
        hysteresis_width_c=float(rng.uniform(1.0, 5.0)), drift_ug_per_h=drift,
        channel_lag_s=lag, channel_lsb_c=chan_lsb,
        channel_offset_c=float(rng.uniform(-2.0, 2.0)),
        channel_noise_c=float(rng.uniform(0.002, 0.02)),
        noise_density_ug_rthz=density, accel_lsb_g=lsb, vib_sd_g=vib,
        accel_unit=str(rng.choice(list(UNIT_SCALE))), kinds=tuple(kinds))
