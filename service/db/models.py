"""SQLAlchemy 2.x models: the persisted state of rigs, campaigns, measurements and calibrations.

Invariants the database itself enforces (so they hold with several service
processes on one PostgreSQL):

* ``measurements``: unique (campaign_id, step, position) -- no measurement is
  ever stored twice, whatever crashes and restarts happen.
* ``rig_leases``: one row per rig at most (primary key ``rig``); a process owns
  a rig -- and runs its one active campaign -- only while it holds the lease.
  A process that dies stops renewing; another takes over after ``lease_until``.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import (
    JSON,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    PrimaryKeyConstraint,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


def utcnow() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


class Base(DeclarativeBase):
    type_annotation_map = {dict[str, Any]: JSON, list[Any]: JSON}


class Rig(Base):
    """A chamber + turntable + sensor line.

    ``chamber``/``turntable``/``sensors`` hold driver config; the chamber's
    ``range_c: [lo, hi]`` bounds the setpoints a campaign may ask for.
    """

    __tablename__ = "rigs"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    chamber: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    turntable: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    sensors: Mapped[list[Any]] = mapped_column(JSON, default=list)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class RigLease(Base):
    """Who runs the rig now.

    Claimed with an INSERT, renewed or taken over with a conditional UPDATE.
    """

    __tablename__ = "rig_leases"
    rig: Mapped[str] = mapped_column(String(64), ForeignKey("rigs.name"), primary_key=True)
    campaign_id: Mapped[int] = mapped_column(Integer, ForeignKey("campaigns.id"))
    owner: Mapped[str] = mapped_column(String(128))  # "<host>:<pid>:<uuid>" of the process
    lease_until: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True))


class Sensor(Base):
    __tablename__ = "sensors"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(64), unique=True)
    model: Mapped[str] = mapped_column(String(64), default="ADXL355")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Campaign(Base):
    """A soak campaign: its spec, state machine state and persisted cursor.

    ``spec`` is the validated POST body (setpoints_c, soak_min, positions,
    samples_per_position, ...). The cursor (``cursor_step``, ``cursor_phase``,
    ``cursor_position``) says where execution stands; the measurements table is
    the ground truth for what has been measured, the cursor is a fast hint.
    ``requested_action`` carries pause/resume/abort from the API (any process)
    to the runner, which acts on it at its next safe point.
    """

    __tablename__ = "campaigns"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rig: Mapped[str] = mapped_column(String(64), ForeignKey("rigs.name"), index=True)
    sensor: Mapped[str] = mapped_column(String(64), index=True)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    state: Mapped[str] = mapped_column(String(16), index=True, default="queued")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    started_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))
    finished_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))
    cursor_step: Mapped[int] = mapped_column(Integer, default=0)
    cursor_phase: Mapped[str] = mapped_column(String(16), default="ramp")
    cursor_position: Mapped[int] = mapped_column(Integer, default=0)
    # Live progress as the API returns it (chamber_c, setpoint_c, eta_s, fraction, ...).
    progress: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    requested_action: Mapped[str | None] = mapped_column(String(16))
    suspended_reason: Mapped[str | None] = mapped_column(Text)
    error: Mapped[str | None] = mapped_column(Text)
    calibration_id: Mapped[int | None] = mapped_column(Integer)
    schedule_id: Mapped[int | None] = mapped_column(Integer)
    # Simulated-campaign time origin (s) so t_s stays continuous across restarts.
    t0_s: Mapped[float | None] = mapped_column(Float)
    # Per-step facts (soak start/end, stability decision, flags) as a JSON list.
    steps_log: Mapped[list[Any]] = mapped_column(JSON, default=list)
    # Several-sensor campaigns: serial → why it was dropped; serial → its calibration id.
    sensors_dropped: Mapped[dict[str, str] | None] = mapped_column(JSON)
    calibration_ids: Mapped[dict[str, int] | None] = mapped_column(JSON)
    # The dry run's prediction, stored at creation (service.dry_run.prediction: duration_s,
    # ramp_s, soak_s, positions_s, counts; duration_s None with ``why`` when it cannot be
    # predicted). NULL: created before migration 0008, filled on first read. None is SQL
    # NULL (not JSON null), so "not computed yet" is one value the conditional fill can test.
    dry_run: Mapped[dict[str, Any] | None] = mapped_column(JSON(none_as_null=True))


class Measurement(Base):
    """One averaged static position: a row of recording format v1."""

    __tablename__ = "measurements"
    __table_args__ = (UniqueConstraint("campaign_id", "sensor", "step", "position",
                                       name="uq_meas_sensor_cursor"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaigns.id"), index=True)
    # The sensor read (several per campaign since migration 0005_multi_sensor); the engine
    # always writes it, NULL only in rows inserted by hand (read as the campaign's sensor).
    sensor: Mapped[str | None] = mapped_column(String(64), index=True)
    step: Mapped[int] = mapped_column(Integer)
    position: Mapped[int] = mapped_column(Integer)
    t_s: Mapped[float] = mapped_column(Float)
    setpoint_c: Mapped[float] = mapped_column(Float)
    chamber_c: Mapped[float | None] = mapped_column(Float)
    sensor_c: Mapped[float | None] = mapped_column(Float)
    ref_x: Mapped[float] = mapped_column(Float)
    ref_y: Mapped[float] = mapped_column(Float)
    ref_z: Mapped[float] = mapped_column(Float)
    ax: Mapped[float] = mapped_column(Float)
    ay: Mapped[float] = mapped_column(Float)
    az: Mapped[float] = mapped_column(Float)
    sd_x: Mapped[float | None] = mapped_column(Float)
    sd_y: Mapped[float | None] = mapped_column(Float)
    sd_z: Mapped[float | None] = mapped_column(Float)
    n: Mapped[int] = mapped_column(Integer)
    attempts: Mapped[int] = mapped_column(Integer, default=1)
    flags: Mapped[str | None] = mapped_column(String(256))  # comma list of failed quality checks
    # The pose the rig commanded for this reading (migration 0009_measurement_pose): the
    # unit quaternion, scalar first, qw ≥ 0, of R mapping sensor to lab coordinates, so
    # ref = |g| Rᵀ (0, 0, 1) (drivers.geometry.pose_quaternion; docs/recording.md,
    # "Project additions"). NULL where the pose is not known: a hand-placed fixture is
    # asked for a direction only, its heading about gravity is the operator's.
    pose_qw: Mapped[float | None] = mapped_column(Float)
    pose_qx: Mapped[float | None] = mapped_column(Float)
    pose_qy: Mapped[float | None] = mapped_column(Float)
    pose_qz: Mapped[float | None] = mapped_column(Float)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class SoakProbe(Base):
    """One die-temperature probe taken during a soak (migration 0006_soak_probes).

    The soak decision's own measurements: the campaign measures the sensor's
    ``temperature_rate`` gain from them (service/engine/rate_gain.py) and a resumed
    campaign reloads them. ``pose`` is the table's commanded angles (deg, "a,b[,c]"),
    the key under which probes of different soaks compare (``ref_*`` its gravity
    reference, NULL when the table's geometry gives none); ``soak_start_t_s`` tells one
    soak of a step from a later re-soak of the same step.
    """

    __tablename__ = "soak_probes"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaigns.id"), index=True)
    sensor: Mapped[str | None] = mapped_column(String(64))
    step: Mapped[int] = mapped_column(Integer)
    soak_start_t_s: Mapped[float] = mapped_column(Float)
    pose: Mapped[str] = mapped_column(String(64))
    t_s: Mapped[float] = mapped_column(Float)
    setpoint_c: Mapped[float] = mapped_column(Float)
    chamber_c: Mapped[float | None] = mapped_column(Float)
    sensor_c: Mapped[float | None] = mapped_column(Float)
    ref_x: Mapped[float | None] = mapped_column(Float)
    ref_y: Mapped[float | None] = mapped_column(Float)
    ref_z: Mapped[float | None] = mapped_column(Float)
    ax: Mapped[float] = mapped_column(Float)
    ay: Mapped[float] = mapped_column(Float)
    az: Mapped[float] = mapped_column(Float)
    n: Mapped[int] = mapped_column(Integer)


class Calibration(Base):
    __tablename__ = "calibrations"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    sensor: Mapped[str] = mapped_column(String(64), index=True)
    campaign_id: Mapped[int | None] = mapped_column(ForeignKey("campaigns.id"))
    created_at: Mapped[dt.datetime] = mapped_column(
        DateTime(timezone=True), default=utcnow, index=True
    )
    valid_lo_c: Mapped[float] = mapped_column(Float)
    valid_hi_c: Mapped[float] = mapped_column(Float)
    rmse_ug: Mapped[float] = mapped_column(Float)
    model_version: Mapped[str] = mapped_column(String(32))
    model: Mapped[dict[str, Any]] = mapped_column(JSON)  # the model document (calibrate -o)
    report: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    provenance: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)


class CalibrationParameter(Base):
    """One SFEM parameter's thermal polynomial of one calibration (migration 0007).

    Copied from the model document when the calibration is stored
    (service/db/calibration_parameters.py) so lot statistics read numbers, not JSON:
    ``p(T) = sum_j c<j> * (T - centre_c)**j`` (the seed paper's Eq. 8 in physical units),
    ``c0``…``c10`` (NULL above the polynomial's degree). ``sensor``, ``reported_model``,
    ``centre_c`` and the valid range repeat the calibration's, so one table answers.
    """

    __tablename__ = "calibration_parameters"
    __table_args__ = (PrimaryKeyConstraint("calibration_id", "name"),)
    calibration_id: Mapped[int] = mapped_column(
        ForeignKey("calibrations.id", ondelete="CASCADE"))
    name: Mapped[str] = mapped_column(String(16))  # bx … mz
    sensor: Mapped[str] = mapped_column(String(64), index=True)
    reported_model: Mapped[str | None] = mapped_column(String(64))
    centre_c: Mapped[float | None] = mapped_column(Float)
    valid_lo_c: Mapped[float | None] = mapped_column(Float)
    valid_hi_c: Mapped[float | None] = mapped_column(Float)
    unit: Mapped[str] = mapped_column(String(32))
    tempco_unit: Mapped[str] = mapped_column(String(32))
    c0: Mapped[float | None] = mapped_column(Float)
    c1: Mapped[float | None] = mapped_column(Float)
    c2: Mapped[float | None] = mapped_column(Float)
    c3: Mapped[float | None] = mapped_column(Float)
    c4: Mapped[float | None] = mapped_column(Float)
    c5: Mapped[float | None] = mapped_column(Float)
    c6: Mapped[float | None] = mapped_column(Float)
    c7: Mapped[float | None] = mapped_column(Float)
    c8: Mapped[float | None] = mapped_column(Float)
    c9: Mapped[float | None] = mapped_column(Float)
    c10: Mapped[float | None] = mapped_column(Float)


class Schedule(Base):
    __tablename__ = "schedules"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign: Mapped[dict[str, Any]] = mapped_column(JSON)  # campaign POST body
    at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))
    cron: Mapped[str | None] = mapped_column(String(128))
    timezone: Mapped[str | None] = mapped_column(String(64))  # IANA name the cron reads in
    next_run_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True), index=True)
    last_run_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))
    last_campaign_id: Mapped[int | None] = mapped_column(Integer)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    # The dry run's prediction of each campaign it fires (as Campaign.dry_run).
    dry_run: Mapped[dict[str, Any] | None] = mapped_column(JSON(none_as_null=True))


class ApiToken(Base):
    __tablename__ = "api_tokens"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str | None] = mapped_column(String(128))
    role: Mapped[str] = mapped_column(String(16))
    token_hash: Mapped[str] = mapped_column(String(128), unique=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    last_used_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))
    # NULL = never expires / not revoked; a revoked or expired token is refused (401) at once.
    expires_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))
    revoked_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))


class PlacementRequest(Base):
    """The hand-placement a manual turntable asks for now (docs/manual-fixtures.md).

    One row per campaign, overwritten by each new request: ``state`` is
    ``pending`` (waiting for the operator), ``confirmed`` (the operator says it
    is placed; the driver checks it) or ``accepted`` (the check passed).
    """

    __tablename__ = "placement_requests"
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaigns.id"), primary_key=True)
    seq: Mapped[int] = mapped_column(Integer, default=1)  # requests issued so far (re-issues count)
    position: Mapped[int] = mapped_column(Integer)  # index in the campaign's schedule
    ref_x: Mapped[float] = mapped_column(Float)  # asked gravity direction, sensor frame (unit)
    ref_y: Mapped[float] = mapped_column(Float)
    ref_z: Mapped[float] = mapped_column(Float)
    instruction: Mapped[str] = mapped_column(Text)
    sketch: Mapped[str] = mapped_column(Text)
    reason: Mapped[str | None] = mapped_column(Text)  # why it was re-issued (None: first ask)
    state: Mapped[str] = mapped_column(String(16), default="pending")
    requested_at: Mapped[dt.datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    confirmed_at: Mapped[dt.datetime | None] = mapped_column(DateTime(timezone=True))


# Registers the listener that fills calibration_parameters whenever a calibration is stored.
from service.db import calibration_parameters as _calibration_parameters  # noqa: E402,F401
