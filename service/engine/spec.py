"""The campaign spec: one pydantic model that the API validates and the engine reads.

:class:`CampaignSpec` is the whole spec (the POST body of ``/api/v1/campaigns``
less ``rig``/``sensor``, which :class:`service.api.schemas.CampaignCreate`
adds). Every key the engine reads is a typed, bounded field here, so a value a
rig's devices would refuse (``samples_per_position`` 200000 against the
bridge's 1..100000, ``range_g`` 3 against the ADXL355's ±2/4/8 g) is a 422 at
the door instead of a failure at 2 a.m. Numbers are strict: a JSON boolean is
not a number (``[false, true]`` is not ``[0, 1]``) and an integer field takes
no fractions. :class:`RunSpec` is a frozen, derived *view* of a validated spec
(seconds instead of minutes, the stability and quality configs assembled), and
:func:`parse_spec` builds it from a stored spec through the same model.

The defaults are the seed paper's protocol (section 3: −40…60 °C in 10 °C steps,
~1 h soak per step, the 24 positions of Table 1, 200 samples per position).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from calibration.campaign_plan import CAMPAIGN_RAMP_C_PER_MIN
from service.engine.quality import QualityLimits
from service.engine.stability import (
    DEFAULT_DRIFT_BUDGET,
    DEFAULT_EDGE_TOL_C,
    DEFAULT_GRADIENT_LAG_S,
    DEFAULT_STEP_TOL_C,
    DEFAULT_TEMPCO_UG_PER_C,
    StabilityConfig,
    temperature_budget_c,
)
from service.engine.suspenders import DEFAULT_BAND_C, DEFAULT_CLEAR_S

DEFAULT_SETPOINTS_C = [-40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0]

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

# Strict numbers: a JSON boolean is refused; ints are accepted where floats are expected.
Float = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Int = Annotated[int, Field(strict=True)]
TempC = Annotated[Float, Field(ge=PLAUSIBLE_C[0], le=PLAUSIBLE_C[1])]


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
    """Every campaign key the engine reads, typed and bounded (units in the names)."""

    model_config = ConfigDict(extra="forbid")

    # --- the contract fields (docs/api.md) --------------------------------------------
    setpoints_c: list[TempC] = Field(
        default_factory=lambda: list(DEFAULT_SETPOINTS_C), min_length=1, max_length=200,
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
    expected_sd_g: Float = _f(QualityLimits.expected_sd_g, MIN_SD_G, 1.0, open_lo=False,
                              doc="rms noise of one raw sample, g")
    max_span_c: Float = _f(QualityLimits.max_span_c, 0, 50,
                           doc="die temperature movement allowed in one capture, °C")
    temp_noise_c: Float = _f(QualityLimits.temp_noise_c, 0, 10, open_lo=False,
                             doc="rms noise of the raw temperature channel, °C")

    # --- devices and timing --------------------------------------------------------------
    ramp_c_per_min: Float = _f(CAMPAIGN_RAMP_C_PER_MIN, 0, REGISTER_MAX_RAMP_C_PER_MIN,
                               doc="chamber setpoint ramp, °C/min (≤ the rig's max rate)")
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

    @model_validator(mode="after")
    def _soak_window_is_ordered(self) -> CampaignSpec:
        # The defaults as run_spec applies them: min(10, soak_min) and 2 × soak_min.
        lo_min = _or(self.min_soak_min, min(10.0, self.soak_min))
        hi_min = _or(self.max_soak_min, 2.0 * self.soak_min)
        if lo_min > hi_min:
            raise ValueError(
                f"min_soak_min {lo_min:g} is above max_soak_min {hi_min:g}: a soak cannot end "
                "before its earliest end; lower min_soak_min or raise max_soak_min")
        return self

    @model_validator(mode="after")
    def _derived_budget_is_usable(self) -> CampaignSpec:
        # The floors above keep this positive; the check names the fields if a mix still
        # underflows or overflows (the engine would refuse it at start, a 500 at the door).
        if self.temp_budget_c is not None:
            return self
        budget_c = temperature_budget_c(
            self.expected_sd_g / self.samples_per_position ** 0.5, self.tempco_ug_per_c,
            self.drift_budget)
        if not (math.isfinite(budget_c) and budget_c > 0.0):
            raise ValueError(
                f"the die-temperature budget derived from expected_sd_g, samples_per_position, "
                f"tempco_ug_per_c and drift_budget is {budget_c:g} °C; give temp_budget_c or "
                "realistic values of those fields")
        return self

    @model_validator(mode="after")
    def _ramp_needs_a_range(self) -> CampaignSpec:
        if self.method != "ramp":
            return self
        if max(self.setpoints_c) <= min(self.setpoints_c):
            raise ValueError(
                "method 'ramp' ramps through the setpoints' range and back: give at least two "
                "different setpoints (its ends, e.g. [-40, 60])")
        if self.rate_gain == "measured":
            raise ValueError(
                "rate_gain 'measured' is a soak's (measured from the soak probes); a ramp "
                "campaign's fit measures the rate gain from its heating and cooling legs: "
                "leave rate_gain out")
        return self

    @model_validator(mode="after")
    def _measured_rate_needs_precise_probes(self) -> CampaignSpec:
        if (self.rate_gain == "measured" and self.soak_probe_samples is not None
                and self.soak_probe_samples < MIN_MEASURED_PROBE_SAMPLES):
            raise ValueError(
                f"rate_gain 'measured' needs soak_probe_samples >= "
                f"{MIN_MEASURED_PROBE_SAMPLES} (got {self.soak_probe_samples}): the gain is "
                "measured from the probes")
        return self


# The contract fields; every other field of CampaignSpec is an engine tuning key.
CONTRACT_FIELDS = ("setpoints_c", "soak_min", "positions", "samples_per_position", "method")
TUNING_KEYS = frozenset(CampaignSpec.model_fields) - set(CONTRACT_FIELDS)


@dataclass(frozen=True)
class RunSpec:
    """A validated :class:`CampaignSpec` as the runner uses it (times in seconds)."""

    setpoints_c: list[float]
    positions: str
    samples_per_position: int
    stability: StabilityConfig
    quality: QualityLimits
    on_max_soak: str = "continue"  # continue | fail
    ramp_c_per_min: float = CAMPAIGN_RAMP_C_PER_MIN
    soak_poll_s: float = 60.0  # cheap sensor/chamber poll period during a soak
    soak_probe_samples: int = 8  # samples per cheap die-temperature probe
    rate_gain: str = "assumed"  # assumed (gradient_lag_s) | measured (soak_rate.py, corrected)
    settle_s: float = 5.0  # wait after in-position before acquiring (table ringing)
    move_timeout_s: float = 120.0
    safe_c: float | None = None  # every exit leaves the chamber here (None: the rig's own)
    range_g: float = 2.0
    odr_hz: float = 62.5
    retry_attempts: int = 4  # tries of one device call before the campaign suspends
    retry_backoff_s: float = 1.0  # first back-off, doubled each try
    suspend_poll_s: float = 30.0
    suspend_limit_s: float = 1800.0  # suspended longer than this: fail the campaign
    chamber_band_c: float = DEFAULT_BAND_C  # air this far off the setpoint while measuring
    suspend_clear_s: float = DEFAULT_CLEAR_S  # a chamber condition clear this long: resume
    position_order: str = "travel"  # travel | random | balanced | table (position_order.py)
    position_order_seed: int | None = None
    method: str = "soak"  # soak | ramp (calibration/ramp_plan.py)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return len(self.setpoints_c)


# RunSpec fields copied as they are from the validated spec.
_DIRECT = ("ramp_c_per_min", "soak_poll_s", "settle_s", "safe_c",
           "odr_hz", "retry_attempts", "retry_backoff_s", "suspend_poll_s", "suspend_limit_s",
           "chamber_band_c", "suspend_clear_s", "move_timeout_s", "on_max_soak", "positions",
           "samples_per_position", "rate_gain", "position_order", "position_order_seed", "method")


def run_spec(spec: CampaignSpec) -> RunSpec:
    """The runner's view of a validated spec (the seed's protocol where keys are absent)."""
    soak_min = spec.soak_min
    quality = QualityLimits(expected_sd_g=spec.expected_sd_g, max_span_c=spec.max_span_c,
                            temp_noise_c=spec.temp_noise_c)
    # What the thermal model can absorb: a fraction of one reading's noise over the
    # sensor's tempco (docs/engine.md, "Stability decision").
    budget_c = spec.temp_budget_c
    if budget_c is None:
        budget_c = temperature_budget_c(
            quality.expected_sd_g / spec.samples_per_position ** 0.5,
            spec.tempco_ug_per_c, spec.drift_budget)
    stab = StabilityConfig(
        policy=spec.stability,
        soak_s=soak_min * 60.0,
        min_soak_s=_or(spec.min_soak_min, min(10.0, soak_min)) * 60.0,
        max_soak_s=_or(spec.max_soak_min, 2.0 * soak_min) * 60.0,
        tol_c=spec.tol_c,
        dwell_s=_or(spec.dwell_min, min(5.0, soak_min)) * 60.0,
        temp_budget_c=budget_c,
        gradient_lag_s=spec.gradient_lag_s,
        tempco_ug_per_c=spec.tempco_ug_per_c,
        step_tol_c=spec.step_tol_c,
        edge_tol_c=spec.edge_tol_c,
        die_tol_c=spec.die_tol_c,
    )
    probe_n = spec.soak_probe_samples
    if probe_n is None:
        probe_n = (DEFAULT_MEASURED_PROBE_SAMPLES if spec.rate_gain == "measured"
                   else DEFAULT_PROBE_SAMPLES)
    return RunSpec(
        setpoints_c=[float(v) for v in spec.setpoints_c],
        soak_probe_samples=probe_n,
        stability=stab,
        quality=quality,
        range_g=float(spec.range_g),
        **{k: getattr(spec, k) for k in _DIRECT},
    )


def parse_spec(stored: dict[str, Any]) -> RunSpec:
    """A :class:`RunSpec` from a stored campaign spec, validated by :class:`CampaignSpec`.

    Keys that are not part of the spec (``rig``, ``sensor``, and anything a
    future contract adds) are kept in ``extra`` and not validated here; a bad
    value of a known key raises ``pydantic.ValidationError`` (a ``ValueError``).
    """
    known = {k: v for k, v in stored.items() if k in CampaignSpec.model_fields}
    run = run_spec(CampaignSpec.model_validate(known))
    extra = {k: v for k, v in stored.items() if k not in CampaignSpec.model_fields}
    return RunSpec(**{**run.__dict__, "extra": extra})


def _or(value: float | None, default: float) -> float:
    return default if value is None else value


def schedule_refs(name: str) -> np.ndarray:
    """Unit gravity references (n, 3) of a named schedule (the calibration core owns them)."""
    from calibration.schedules import get_schedule

    return np.asarray(get_schedule(name), float)
