"""Pydantic bodies and responses of docs/api.md (so /openapi.json describes every one).

The campaign body, :class:`CampaignCreate`, is the one campaign spec
(``calibration.campaign_spec``) plus ``rig`` and ``sensor`` (``service.engine.spec``).
"""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

# The campaign request is the service's, not the HTTP layer's (the scheduler validates
# stored schedules with it): defined with the spec, named here for the API's schema.
from calibration.campaign_spec import TUNING_KEYS
from service.engine.spec import CampaignCreate

CampaignState = Literal["queued", "running", "paused", "completed", "failed", "aborted"]
Phase = Literal["ramp", "soak", "positions", "fitting"]
Role = Literal["viewer", "operator", "admin"]


class RigOut(BaseModel):
    name: str
    chamber: dict[str, Any]
    turntable: dict[str, Any]
    sensors: list[Any]
    busy: bool = Field(description="a campaign is running or paused on this rig")


class RigCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$")
    chamber: dict[str, Any] = Field(
        description="driver config; `range_c: [lo, hi]` bounds the setpoints"
    )
    turntable: dict[str, Any] = Field(default_factory=dict)
    sensors: list[Any] = Field(default_factory=list)


# Optional keys the engine reads to tune a run (calibration/campaign_spec.py).
ENGINE_TUNING_KEYS = TUNING_KEYS


class Progress(BaseModel):
    step: int
    steps: int
    phase: Phase
    position: int
    positions: int | None
    fraction: float = Field(ge=0.0, le=1.0)
    chamber_c: float | None
    setpoint_c: float | None
    eta_s: float | None
    eta_wall_s: float | None = Field(
        default=None, description="eta_s on the wall clock (shorter on a sped-up sim rig)")
    method: Literal["soak", "ramp"] = Field(
        default="soak", description="the campaign's method; a ramp's steps are its sweeps")
    leg_target_c: float | None = Field(
        default=None, description="a ramp: where the chamber is heading on this leg, °C")


class CampaignOut(BaseModel):
    id: int
    rig: str
    sensor: str = Field(description="the campaign's (first) sensor")
    sensors: list[str] = Field(default_factory=list,
                               description="every sensor of the campaign, in order")
    sensors_dropped: dict[str, str] = Field(
        default_factory=dict, description="sensor → why it was dropped during the run")
    state: CampaignState
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    progress: Progress
    calibration_id: int | None
    calibration_ids: dict[str, int] = Field(
        default_factory=dict, description="sensor → its calibration id (one per sensor)")
    error: str | None
    requested_action: str | None = Field(
        description="pause/resume/abort waiting for the runner's next safe point"
    )
    suspended_reason: str | None
    spec: dict[str, Any]
    schedule_id: int | None
    predicted_duration_s: float | None = Field(
        default=None,
        description="the dry run's estimate of the whole campaign in rig time, s "
        "(ramps, soaks, moves, settles, acquisitions; a sped-up sim rig: divide by its speed)",
    )


class CalibrationSummary(BaseModel):
    id: int
    sensor: str
    campaign_id: int | None
    created_at: dt.datetime
    valid_c: tuple[float, float]
    rmse_ug: float
    model_version: str


class CoefficientsOut(BaseModel):
    """calibrated = matrix · (raw − bias_g)."""

    calibration_id: int
    temperature_c: float
    matrix: list[list[float]]
    bias_g: list[float]
    extrapolated: bool


def _one_trigger_schema(schema: dict[str, Any]) -> None:
    """OpenAPI: exactly one of ``at`` / ``cron`` (each a non-null value when given)."""
    props = schema.get("properties", {})
    props["at"] = {"type": "string", "format": "date-time", "title": "At",
                   "description": "ISO-8601, in the future; naive means UTC"}
    props["cron"] = {"type": "string", "title": "Cron", "minLength": 1, "maxLength": 128,
                     "examples": ["0 20 * * 1-5"],
                     "description": "five fields, read in `timezone` (default UTC)"}
    props["timezone"] = {"type": "string", "title": "Timezone", "maxLength": 64,
                         "examples": ["Europe/Berlin"],
                         "description": "IANA time zone of the lab's wall clock for `cron`; "
                         "default UTC"}
    schema["oneOf"] = [
        {"required": ["at"],
         "not": {"anyOf": [{"required": ["cron"]}, {"required": ["timezone"]}]}},
        {"required": ["cron"], "not": {"required": ["at"]}},
    ]


class ScheduleCreate(BaseModel):
    """A one-shot (``at``) or repeating (``cron``) campaign: exactly one of the two."""

    model_config = ConfigDict(extra="forbid", json_schema_extra=_one_trigger_schema)
    campaign: CampaignCreate
    at: dt.datetime | None = Field(default=None, description="ISO-8601; naive means UTC")
    cron: str | None = Field(default=None, min_length=1, max_length=128,
                             description="read in `timezone` (default UTC)")
    timezone: str | None = Field(
        default=None,
        max_length=64,
        examples=["Europe/Berlin"],
        description="IANA time zone of the lab's wall clock for `cron`; default UTC",
    )

    @model_validator(mode="before")
    @classmethod
    def _no_explicit_nulls(cls, data: Any) -> Any:
        # The schema says "a value when given": null is not a way to leave a trigger out.
        if isinstance(data, dict):
            for key in ("at", "cron", "timezone"):
                if key in data and data[key] is None:
                    raise ValueError(f"'{key}' is null; give a value or leave the key out")
        return data

    @model_validator(mode="after")
    def _exactly_one_trigger(self) -> ScheduleCreate:
        if (self.at is None) == (self.cron is None):
            raise ValueError("give exactly one of 'at' (ISO-8601) or 'cron'")
        if self.timezone is not None and self.cron is None:
            raise ValueError("'timezone' applies to 'cron'; give 'at' with its UTC offset")
        return self


class ScheduleOut(BaseModel):
    id: int
    campaign: dict[str, Any]
    at: dt.datetime | None
    cron: str | None
    timezone: str | None
    next_run_at: dt.datetime | None
    last_run_at: dt.datetime | None
    last_campaign_id: int | None
    created_at: dt.datetime
    predicted_duration_s: float | None = Field(
        default=None, description="the dry run's estimate of each campaign in rig time, s"
    )


class HealthOut(BaseModel):
    status: Literal["ok", "error"]
    database: Literal["ok", "error"]
    version: str


class TokenCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    role: Role
    name: str | None = Field(default=None, max_length=128)


class TokenCreated(BaseModel):
    id: int
    role: Role
    name: str | None
    token: str = Field(description="shown once; the service keeps only its hash")


class ErrorOut(BaseModel):
    detail: Any
