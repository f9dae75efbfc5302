"""Pydantic bodies and responses of spec/api.md (so /openapi.json describes every one)."""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

from service.engine.spec import TUNING_KEYS

CampaignState = Literal["queued", "running", "paused", "completed", "failed", "aborted"]
Phase = Literal["ramp", "soak", "positions", "fitting"]
Role = Literal["viewer", "operator", "admin"]

DEFAULT_SETPOINTS_C: list[float] = [float(t) for t in range(-40, 61, 10)]


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


# Optional keys the engine reads to tune a run (service/engine/spec.py); others are typos.
ENGINE_TUNING_KEYS = TUNING_KEYS


class CampaignCreate(BaseModel):
    """A campaign request; everything but ``rig`` and ``sensor`` has the lab's default.

    Engine tuning keys (``ENGINE_TUNING_KEYS``, e.g. ``ramp_c_per_min``) pass through
    to the stored spec; any other extra key is rejected (422 naming it).
    """

    model_config = ConfigDict(extra="allow")
    rig: str = Field(min_length=1, max_length=64, examples=["sim"])
    sensor: str = Field(min_length=1, max_length=64, examples=["SN-0001"])
    setpoints_c: list[float] = Field(
        default_factory=lambda: list(DEFAULT_SETPOINTS_C), min_length=1, max_length=200
    )
    soak_min: float = Field(default=60.0, gt=0, le=24 * 60)
    positions: str = Field(default="table1", description="position schedule name")
    samples_per_position: int = Field(default=200, ge=1, le=1_000_000)

    @model_validator(mode="before")
    @classmethod
    def _only_known_extras(cls, data: Any) -> Any:
        if isinstance(data, dict):
            unknown = set(data) - set(cls.model_fields) - ENGINE_TUNING_KEYS
            if unknown:
                raise PydanticCustomError(
                    "extra_forbidden",
                    "unknown field(s) {fields}; contract fields: rig, sensor, setpoints_c, "
                    "soak_min, positions, samples_per_position (plus engine tuning keys)",
                    {"fields": ", ".join(sorted(unknown))},
                )
        return data


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


class CampaignOut(BaseModel):
    id: int
    rig: str
    sensor: str
    state: CampaignState
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    progress: Progress
    calibration_id: int | None
    error: str | None
    requested_action: str | None = Field(
        description="pause/resume/abort waiting for the runner's next safe point"
    )
    suspended_reason: str | None
    spec: dict[str, Any]
    schedule_id: int | None


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


class ScheduleCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    campaign: CampaignCreate
    at: dt.datetime | None = Field(default=None, description="ISO-8601; naive means UTC")
    cron: str | None = Field(
        default=None, examples=["0 20 * * 1-5"], description="read in `timezone` (default UTC)"
    )
    timezone: str | None = Field(
        default=None,
        examples=["Europe/Berlin"],
        description="IANA time zone of the lab's wall clock for `cron`; default UTC",
    )

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
