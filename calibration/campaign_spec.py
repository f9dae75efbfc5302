"""The campaign spec, once: every key of a thermal-soak campaign, typed, bounded, defaulted here.

:class:`CampaignSpec` is the one shape of a campaign's protocol. The service
validates a ``POST /api/v1/campaigns`` body with it (``service.engine.spec``
adds what its engine refuses and the request's ``rig``/``sensor``), the
engine reads it (``service.engine.spec.parse_spec``), the plan interprets it
(:func:`calibration.campaign_plan.campaign_plan`), the dry run predicts it and
the offline simulator builds one for its own protocol. It lives in the
calibration core so that all of them import it without climbing into the
service. It is immutable (a frozen pydantic model): what was validated is
what runs.

Every default is written here and nowhere else. The defaults are the seed
paper's protocol (section 3: −40…60 °C in 10 °C steps, ~1 h soak per step, the
24 positions of Table 1, 200 samples per position) and the engine's: the
positions of a step in the order of least table travel (``position_order``
``travel``). A caller with another protocol says so: the offline simulator
passes its ``table`` order and its rig's ramp explicitly.

Numbers are strict: a JSON boolean is not a number (``[false, true]`` is not
``[0, 1]``) and an integer field takes no fractions. A value a rig's devices
would refuse (``samples_per_position`` 200000 against the sensor bridge's
1..100000, ``range_g`` 3 against the ADXL355's ±2/4/8 g) is refused here, naming
the field.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

# The commanded chamber ramp's default, °C/min, is the plan's (the offline twin commands its
# own rig's rate explicitly).
from calibration.campaign_plan import CAMPAIGN_RAMP_C_PER_MIN, RAMP_METHOD_C_PER_MIN

DEFAULT_SETPOINTS_C: tuple[float, ...] = (
    -40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0)

# --- the soak decision's defaults (service/engine/stability.py reads these) ------------
# ADXL355 datasheet: offset tempco ±0.15 mg/°C (max), sensitivity tempco 0.01 %/°C
# (0.1 mg/°C at 1 g): the larger is the output change per °C of temperature error.
DEFAULT_TEMPCO_UG_PER_C = 150.0
# A soak-induced error may add this fraction of the reading noise (≈ 3 % in quadrature).
DEFAULT_DRIFT_BUDGET = 0.25
# Package/board lag behind the die reading while the die moves: ceramic LCC package
# ≈ 0.15 J/K on ≈ 30 K/W of pads and board → R·C ≈ 5 s, doubled for margin.
DEFAULT_GRADIENT_LAG_S = 10.0
# Every position within this of the step's final temperature, so the steps stay where the
# plan put them. Measured (issue 12, docs/benchmarks.md): with the same position noise, soaks
# ending ≈ 1.9 °C from the final value (the former 2 °C, a fifth of the seed's spacing) cost
# a sensor 3–4 % of held-out error, ≈ 0.9 °C nothing measurable.
DEFAULT_STEP_TOL_C = 1.0
# The calibration core's valid range is the step temperatures ± 1 °C; keeping the
# extreme steps within 0.7 °C of their final value leaves 3 σ of a reading's 0.1 °C.
DEFAULT_EDGE_TOL_C = 0.7

# --- the per-position quality checks' defaults (service/engine/quality.py) -------------
# rms noise of one raw sample (ADXL355: 25 µg/√Hz @ 62.5 Hz ODR).
DEFAULT_EXPECTED_SD_G = 2.5e-4
# Die temperature moved during the capture beyond this: not a static reading, °C.
DEFAULT_MAX_SPAN_C = 0.2
# rms noise of one raw temperature-channel sample, °C.
DEFAULT_TEMP_NOISE_C = 0.1

# --- the suspenders' defaults (service/engine/suspenders.py) ---------------------------
DEFAULT_BAND_C = 2.0  # PV farther than this from the setpoint during a sweep: out of band
DEFAULT_CLEAR_S = 60.0  # a condition must stay clear this long (clock s) before resuming

# The sensor bridge's ACQ accepts 1..100000 samples ("ERR 3 n must be 1..100000").
BRIDGE_MAX_SAMPLES = 100_000
# ADXL355 measurement ranges (datasheet, RANGE register): ±2, ±4, ±8 g.
ADXL355_RANGES_G = (2.0, 4.0, 8.0)
# ADXL355 output data rates: 4000 Hz / 2^k, k = 0..10 (datasheet, FILTER register).
ADXL355_MAX_ODR_HZ = 4000.0
# The Eurotherm 3216 SP rate limit is a uint16 in tenths of °C/min: 6553.5 °C/min at most.
# A rig's real capability (``chamber.max_rate_c_per_min``) is checked by the dry run.
REGISTER_MAX_RAMP_C_PER_MIN = 6553.5
# Longest waits a campaign may configure: long enough for any real rig, short enough
# that an abort never waits behind a 1e9 s settle (the audit's stuck rig).
MAX_SETTLE_S = 600.0
MAX_SOAK_MIN = 24 * 60.0
MAX_POLL_S = 3600.0
MAX_SUSPEND_LIMIT_S = 7 * 24 * 3600.0
# Fewest samples per soak probe when the rate gain is measured from the probes: 8-sample
# probes give σ(k) ≈ 25–30 µg per °C/min over a campaign, 200 ≈ 5 (docs/engine.md).
MIN_MEASURED_PROBE_SAMPLES = 200
# Probe size when not given: 8 samples (a die-temperature probe, 0.13 s), or 250 (4 s of
# every 60-s poll) when the rate gain is measured from the probes.
DEFAULT_PROBE_SAMPLES = 8
DEFAULT_MEASURED_PROBE_SAMPLES = 250
# Plausible air temperatures for any climatic chamber; the rig's own range is the dry run's.
PLAUSIBLE_C = (-200.0, 500.0)
# Floors of the noise and tempco figures the soak budget is derived from: far below any
# MEMS accelerometer (the ADXL355's noise is ~25 µg per sample at 62.5 Hz, its tempco
# ~100 µg/°C), far above the denormal floats that would underflow the budget to 0 °C.
MIN_SD_G = 1e-9
MIN_TEMPCO_UG_PER_C = 1e-6
MIN_DRIFT_BUDGET = 1e-6
# Sensor serials travel in URL paths (/api/v1/sensors/{serial}/...): no "/", no spaces.
SERIAL_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.:-]{0,63}$"
# Sensors one campaign may name: a production fixture holds 8…16 (issue 12); 64 leaves room.
MAX_SENSORS = 64

# Strict numbers: a JSON boolean is refused; ints are accepted where floats are expected.
Float = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Int = Annotated[int, Field(strict=True)]
TempC = Annotated[Float, Field(ge=PLAUSIBLE_C[0], le=PLAUSIBLE_C[1])]
Serial = Annotated[str, Field(
    min_length=1, max_length=64, pattern=SERIAL_PATTERN, examples=["SN-0001"],
    description="sensor serial: letters, digits and _ . : - (first a letter or digit), "
    "at most 64",
)]


def _f(default: float | None, lo: float | None = None, hi: float | None = None, *,
       open_lo: bool = True, doc: str) -> Any:
    """A bounded float field: ``lo < x`` (``lo <= x`` when ``open_lo`` is False), ``x <= hi``."""
    bounds: dict[str, float] = {}
    if lo is not None:
        bounds["gt" if open_lo else "ge"] = lo
    if hi is not None:
        bounds["le"] = hi
    return Field(default=default, description=doc, **bounds)


class CampaignSpec(BaseModel):
    """Every key of a campaign, typed and bounded (units in the names), with its default."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    # --- the contract fields (docs/api.md) --------------------------------------------
    setpoints_c: tuple[TempC, ...] = Field(
        default=DEFAULT_SETPOINTS_C, min_length=1, max_length=200,
        description="chamber setpoints in °C, in run order (within the rig's range)")
    soak_min: Float = _f(60.0, 0, MAX_SOAK_MIN, doc="nominal soak per step, minutes")
    positions: str = Field(
        default="table1", min_length=1, max_length=32, pattern=r"^[A-Za-z0-9_+]+$",
        description="position schedule: table1, six, cube14, sphere<N>, a+b")
    samples_per_position: Int = Field(
        default=200, ge=1, le=BRIDGE_MAX_SAMPLES,
        description="samples averaged per position (sensor bridge: 1..100000)")
    method: Literal["soak", "ramp"] = Field(
        default="soak",
        description="soak: the chamber holds each setpoint until the die is stable; ramp: "
        "the chamber ramps through the setpoints' range and back while the table sweeps, "
        "each capture at its die's own temperature (calibration/ramp_plan.py)")
    # Declared before ``sensor`` of the request (pydantic field order: its check sees it).
    sensors: tuple[Serial, ...] | None = Field(
        default=None, min_length=1, max_length=MAX_SENSORS,
        description=f"several sensors calibrated together (1…{MAX_SENSORS}, each once); "
        "none: the one sensor the request names")

    @field_validator("sensors")
    @classmethod
    def _each_sensor_once(cls, sensors: tuple[str, ...] | None) -> tuple[str, ...] | None:
        seen: set[str] = set()
        for serial in sensors or ():
            if serial in seen:
                raise ValueError(f"sensor {serial!r} is named twice")
            seen.add(serial)
        return sensors

    # --- position order (calibration/position_order.py, docs/engine.md) --------------------
    position_order: Literal["travel", "random", "balanced", "table"] = Field(
        default="travel",
        description="order of a step's positions: least table travel, seeded random or "
        "counter-balanced per plateau, or the schedule's")
    position_order_seed: Int | None = Field(
        default=None, ge=0, le=2**32 - 1, validate_default=True,
        description="seed of a random (required) or balanced (default 0) order")

    @field_validator("position_order_seed")
    @classmethod
    def _random_needs_a_seed(cls, seed: int | None, info: ValidationInfo) -> int | None:
        if seed is None and info.data.get("position_order") == "random":
            raise ValueError("a random position order needs a seed, so the order can be "
                             "reproduced (and a resumed step visits the same order)")
        return seed

    # --- stability decision (service/engine/stability.py) ------------------------------
    stability: Literal["predictive", "dwell", "fixed"] = Field(
        default="predictive", description="soak end rule; fixed = exactly soak_min (the seed)")
    min_soak_min: Float | None = _f(None, 0, MAX_SOAK_MIN, open_lo=False,
                                    doc="earliest soak end, min (default min(10, soak_min))")
    max_soak_min: Float | None = _f(None, 0, 2 * MAX_SOAK_MIN,
                                    doc="soak cap, min (default 2 × soak_min)")
    on_max_soak: Literal["continue", "fail"] = Field(
        default="continue", description="at the soak cap: measure anyway (flagged) or fail")
    tol_c: Float = _f(0.3, 0, 10, doc="chamber air band around the setpoint, °C")
    dwell_min: Float | None = _f(None, 0, MAX_SOAK_MIN, open_lo=False,
                                 doc="time in band for policy dwell, min (default min(5, soak))")
    die_tol_c: Float | None = _f(None, 0, 10, doc="optional |T − T∞| rule on the die, °C")
    temp_budget_c: Float | None = _f(None, 0, 10,
                                     doc="rms die-temperature error allowed, °C (derived)")
    tempco_ug_per_c: Float = _f(DEFAULT_TEMPCO_UG_PER_C, MIN_TEMPCO_UG_PER_C, 1e5,
                                open_lo=False, doc="sensor output change per °C, µg/°C")
    drift_budget: Float = _f(DEFAULT_DRIFT_BUDGET, MIN_DRIFT_BUDGET, 10, open_lo=False,
                             doc="soak error allowed as a fraction of one reading's noise")
    gradient_lag_s: Float = _f(DEFAULT_GRADIENT_LAG_S, 0, 3600, open_lo=False,
                               doc="package lag behind the die reading, s")
    rate_gain: Literal["assumed", "measured"] = Field(
        default="assumed",
        description="sensitivity to the die's rate of change: assumed (gradient_lag_s) or "
                    "measured from the soak probes (then the calibration corrects k̂·rate "
                    "and the soak waits for the correction's uncertainty only)")
    step_tol_c: Float = _f(DEFAULT_STEP_TOL_C, 0, 50, doc="every step: |T − T∞|, °C")
    edge_tol_c: Float = _f(DEFAULT_EDGE_TOL_C, 0, 50, doc="extreme steps: sweep offset, °C")

    # --- per-position quality checks (service/engine/quality.py) -----------------------
    expected_sd_g: Float = _f(DEFAULT_EXPECTED_SD_G, MIN_SD_G, 1.0, open_lo=False,
                              doc="rms noise of one raw sample, g")
    max_span_c: Float = _f(DEFAULT_MAX_SPAN_C, 0, 50,
                           doc="die temperature movement allowed in one capture, °C")
    temp_noise_c: Float = _f(DEFAULT_TEMP_NOISE_C, 0, 10, open_lo=False,
                             doc="rms noise of the raw temperature channel, °C")

    # --- devices and timing --------------------------------------------------------------
    ramp_c_per_min: Float = _f(CAMPAIGN_RAMP_C_PER_MIN, 0, REGISTER_MAX_RAMP_C_PER_MIN,
                               open_lo=False,
                               doc="chamber setpoint ramp, °C/min (≤ the rig's max rate); "
                                   "0: step, the chamber moves at its own rate (method "
                                   "'soak' only); default 2 for method 'ramp'")
    soak_poll_s: Float = _f(60.0, 0, MAX_POLL_S, doc="soak poll period, s")
    soak_probe_samples: Int | None = Field(
        default=None, ge=1, le=BRIDGE_MAX_SAMPLES,
        description="samples per die-temperature probe (default 8; 250 with rate_gain "
                    "measured, which needs at least 200)")
    settle_s: Float = _f(5.0, 0, MAX_SETTLE_S, open_lo=False,
                         doc="wait after in-position before acquiring, s")
    move_timeout_s: Float = _f(120.0, 0, MAX_POLL_S, doc="table move timeout, s")
    safe_c: TempC | None = Field(
        default=None, description="chamber temperature at the end, °C (default: the chamber "
        "map's [safe] setpoint_c; 23 °C where the chamber has no map)")
    range_g: Literal[2, 4, 8] = Field(default=2, description="ADXL355 range, ±g")
    odr_hz: Float = _f(62.5, 0, ADXL355_MAX_ODR_HZ, doc="ADXL355 output data rate, Hz")
    retry_attempts: Int = Field(default=4, ge=1, le=20,
                                description="tries of one device call before suspending")
    retry_backoff_s: Float = _f(1.0, 0, 600, open_lo=False, doc="first retry back-off, s")
    suspend_poll_s: Float = _f(30.0, 0, MAX_POLL_S, doc="device poll while suspended, s")
    suspend_limit_s: Float = _f(1800.0, 0, MAX_SUSPEND_LIMIT_S,
                                doc="suspended longer than this fails the campaign, s")
    chamber_band_c: Float = _f(DEFAULT_BAND_C, 0, 50,
                               doc="air farther than this from the setpoint while measuring "
                                   "suspends the campaign (and restarts the soak), °C")
    suspend_clear_s: Float = _f(DEFAULT_CLEAR_S, 0, MAX_POLL_S, open_lo=False,
                                doc="a chamber alarm or band excursion must stay clear this "
                                    "long before the campaign resumes, s")

    # --- what follows from the keys (the defaults that depend on another key) ----------
    @property
    def min_soak_s(self) -> float:
        """Earliest soak end, s: ``min_soak_min``, default min(10 min, ``soak_min``)."""
        return _or(self.min_soak_min, min(10.0, self.soak_min)) * 60.0

    @property
    def max_soak_s(self) -> float:
        """Soak cap, s: ``max_soak_min``, default 2 × ``soak_min``."""
        return _or(self.max_soak_min, 2.0 * self.soak_min) * 60.0

    @property
    def dwell_s(self) -> float:
        """Time in band for the dwell policy, s: ``dwell_min``, default min(5 min, soak)."""
        return _or(self.dwell_min, min(5.0, self.soak_min)) * 60.0

    @property
    def probe_samples(self) -> int:
        """Samples per soak probe: given, or 8 (250 when the rate gain is measured)."""
        if self.soak_probe_samples is not None:
            return self.soak_probe_samples
        return (DEFAULT_MEASURED_PROBE_SAMPLES if self.rate_gain == "measured"
                else DEFAULT_PROBE_SAMPLES)

    @model_validator(mode="after")
    def _soak_window_is_ordered(self) -> CampaignSpec:
        if self.min_soak_s > self.max_soak_s:
            raise ValueError(
                f"min_soak_min {self.min_soak_s / 60.0:g} is above max_soak_min "
                f"{self.max_soak_s / 60.0:g}: a soak cannot end before its earliest end; "
                "lower min_soak_min or raise max_soak_min")
        return self

    @model_validator(mode="before")
    @classmethod
    def _ramp_method_default_rate(cls, data: Any) -> Any:
        # A ramp campaign measures while the chamber moves, so its rate sets both the
        # campaign's time and what the legs identify: its own default (campaign_plan).
        if isinstance(data, dict) and data.get("method") == "ramp" \
                and data.get("ramp_c_per_min") is None:
            return {**data, "ramp_c_per_min": RAMP_METHOD_C_PER_MIN}
        return data

    @field_validator("ramp_c_per_min")
    @classmethod
    def _ramp_method_needs_a_ramp(cls, rate: float, info: ValidationInfo) -> float:
        # A soak's calibration does not depend on the ramp between steps (the soak decides
        # stability), so 0 (step) is a soak's choice; a ramp campaign measures while the
        # chamber ramps, at the commanded rate (calibration/ramp_plan.py). A field validator
        # (``method`` is validated before it), so the refusal names ramp_c_per_min.
        if info.data.get("method") == "ramp" and not rate > 0:
            raise ValueError(
                "method 'ramp' needs a controlled ramp: ramp_c_per_min 0 means step (the "
                "chamber moves at its own rate), which only method 'soak' accepts; give the "
                "ramp rate, > 0 °C/min")
        return rate

    @model_validator(mode="after")
    def _measured_rate_needs_precise_probes(self) -> CampaignSpec:
        if (self.rate_gain == "measured" and self.soak_probe_samples is not None
                and self.soak_probe_samples < MIN_MEASURED_PROBE_SAMPLES):
            raise ValueError(
                f"rate_gain 'measured' needs soak_probe_samples >= "
                f"{MIN_MEASURED_PROBE_SAMPLES} (got {self.soak_probe_samples}): the gain is "
                "measured from the probes")
        return self


# The contract fields; every other field of CampaignSpec but ``sensors`` is a tuning key.
CONTRACT_FIELDS = ("setpoints_c", "soak_min", "positions", "samples_per_position", "method")
TUNING_KEYS = frozenset(CampaignSpec.model_fields) - {*CONTRACT_FIELDS, "sensors"}


def _or(value: float | None, default: float) -> float:
    return default if value is None else value
