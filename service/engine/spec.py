"""The campaign spec at this service's door, and the engine's view of it.

The spec itself is :class:`calibration.campaign_spec.CampaignSpec` (every key,
its type, bounds and default, written once). Here the service adds only what
is its own:

* :class:`EngineSpec`: the one spec as this engine accepts it: a ramp without a
  range or with the soak's measured rate gain is refused naming the reason, and so
  is a mix of keys whose derived soak budget is not a usable temperature;
* :class:`CampaignCreate`: a campaign request, the spec plus where (``rig``)
  and with what (``sensor``, or the spec's ``sensors``): the POST body of
  ``/api/v1/campaigns`` and the ``campaign`` of a schedule;
* :class:`RunSpec` and :func:`parse_spec`: the runner's view of a stored spec
  (seconds instead of minutes, the stability and quality configs assembled),
  derived from the validated spec, with no default of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import ConfigDict, Field, ValidationInfo, field_validator, model_validator

from calibration.campaign_spec import CampaignSpec, Serial
from service.engine.quality import QualityLimits
from service.engine.stability import StabilityConfig, temperature_budget_c


class EngineSpec(CampaignSpec):
    """The one campaign spec, as this engine runs it (no field, no default of its own)."""

    @model_validator(mode="after")
    def _ramp_needs_a_range(self) -> EngineSpec:
        # The ramp plan (calibration/ramp_plan.py) ramps through the setpoints' range.
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
    def _derived_budget_is_usable(self) -> EngineSpec:
        # The floors of the spec keep this positive; the check names the fields if a mix
        # still underflows or overflows (the engine would refuse it at start, a 500 at the door).
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


class CampaignCreate(EngineSpec):
    """A campaign request: the spec plus where (``rig``) and what (the sensor) to calibrate.

    Everything but ``rig`` and the sensor has the lab's default; every key is typed
    and bounded, and an unknown key is refused (422 naming it). The sensor is named
    by exactly one of ``sensor`` (one) or ``sensors`` (several, each once; issue 12).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    rig: str = Field(min_length=1, max_length=64, examples=["sim"])
    sensor: Serial | None = Field(default=None, validate_default=True,
                                  description="the one sensor calibrated (or use `sensors`)")

    @field_validator("sensor")
    @classmethod
    def _sensor_or_sensors(cls, sensor: str | None, info: ValidationInfo) -> str | None:
        several = info.data.get("sensors")
        if sensor is None and several is None and "sensors" in info.data:
            raise ValueError("name the sensor: 'sensor' (one) or 'sensors' (several)")
        if sensor is not None and several is not None:
            raise ValueError("give 'sensor' or 'sensors', not both")
        return sensor

    @property
    def serials(self) -> list[str]:
        """The campaign's sensors in order (one for ``sensor``)."""
        return list(self.sensors) if self.sensors is not None else [str(self.sensor)]

    def stored(self) -> dict[str, Any]:
        """The request as a campaign row stores it (JSON types; unset optional keys left out)."""
        return self.model_dump(mode="json", exclude_none=True)


def stored_serials(stored: dict[str, Any], first: str | None = None) -> tuple[str, ...]:
    """The sensors a stored campaign spec names, in order: ``sensors``, else its ``sensor``
    (or ``first``, the row's sensor column) as a list of one; empty when it names none."""
    several = stored.get("sensors")
    if isinstance(several, list | tuple) and several:
        return tuple(str(s) for s in several)
    one = stored.get("sensor", first)
    return () if one is None else (str(one),)


@dataclass(frozen=True)
class RunSpec:
    """A validated spec as the runner uses it (times in seconds): derived, no defaults here.

    Every attribute comes from :class:`CampaignSpec` (:func:`run_spec`); ``sensors`` is the
    campaign's serials (a one-sensor campaign: a list of one), ``extra`` the stored keys
    outside the spec's tuning and contract keys (``rig``, ``sensor``, ``sensors``).
    """

    setpoints_c: list[float]
    positions: str
    samples_per_position: int
    method: str
    sensors: tuple[str, ...]
    stability: StabilityConfig
    quality: QualityLimits
    on_max_soak: str  # continue | fail
    ramp_c_per_min: float
    soak_poll_s: float  # cheap sensor/chamber poll period during a soak
    soak_probe_samples: int  # samples per cheap die-temperature probe
    rate_gain: str  # assumed (gradient_lag_s) | measured (from the soak probes, corrected)
    settle_s: float  # wait after in-position before acquiring (table ringing)
    move_timeout_s: float
    safe_c: float | None  # every exit leaves the chamber here (None: the rig's own)
    range_g: float
    odr_hz: float
    retry_attempts: int  # tries of one device call before the campaign suspends
    retry_backoff_s: float  # first back-off, doubled each try
    suspend_poll_s: float
    suspend_limit_s: float  # suspended longer than this: fail the campaign
    chamber_band_c: float  # air this far off the setpoint while measuring
    suspend_clear_s: float  # a chamber condition clear this long: resume
    position_order: str  # travel | random | balanced | table (position_order.py)
    position_order_seed: int | None
    extra: dict[str, Any]

    @property
    def n_steps(self) -> int:
        return len(self.setpoints_c)


# RunSpec fields copied as they are from the validated spec.
_DIRECT = ("ramp_c_per_min", "soak_poll_s", "settle_s", "safe_c", "method",
           "odr_hz", "retry_attempts", "retry_backoff_s", "suspend_poll_s", "suspend_limit_s",
           "chamber_band_c", "suspend_clear_s", "move_timeout_s", "on_max_soak", "positions",
           "samples_per_position", "rate_gain", "position_order", "position_order_seed")


def run_spec(spec: CampaignSpec, sensors: tuple[str, ...] | None = None,
             extra: dict[str, Any] | None = None) -> RunSpec:
    """The runner's view of a validated spec (``sensors``: default the spec's)."""
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
        soak_s=spec.soak_min * 60.0,
        min_soak_s=spec.min_soak_s,
        max_soak_s=spec.max_soak_s,
        tol_c=spec.tol_c,
        dwell_s=spec.dwell_s,
        temp_budget_c=budget_c,
        gradient_lag_s=spec.gradient_lag_s,
        tempco_ug_per_c=spec.tempco_ug_per_c,
        step_tol_c=spec.step_tol_c,
        edge_tol_c=spec.edge_tol_c,
        die_tol_c=spec.die_tol_c,
    )
    return RunSpec(
        setpoints_c=[float(v) for v in spec.setpoints_c],
        sensors=tuple(spec.sensors or ()) if sensors is None else tuple(sensors),
        soak_probe_samples=spec.probe_samples,
        stability=stab,
        quality=quality,
        range_g=float(spec.range_g),
        extra=dict(extra or {}),
        **{k: getattr(spec, k) for k in _DIRECT},
    )



def parse_spec(stored: dict[str, Any]) -> RunSpec:
    """A :class:`RunSpec` from a stored campaign spec, validated by :class:`EngineSpec`.

    Keys that are not part of the spec (``rig``, ``sensor``, and anything a
    future contract adds) are kept in ``extra`` (with ``sensors``, as stored) and
    not validated here; ``sensors`` is the campaign's serials, a one-sensor
    campaign's ``sensor`` as a list of one. A bad value of a known key raises
    ``pydantic.ValidationError`` (a ``ValueError``).
    """
    fields = EngineSpec.model_fields
    spec = EngineSpec.model_validate({k: v for k, v in stored.items() if k in fields})
    extra = {k: v for k, v in stored.items() if k not in fields or k == "sensors"}
    return run_spec(spec, sensors=stored_serials(stored), extra=extra)


def schedule_refs(name: str) -> np.ndarray:
    """Unit gravity references (n, 3) of a named schedule (the calibration core owns them)."""
    from calibration.schedules import get_schedule

    return np.asarray(get_schedule(name), float)
