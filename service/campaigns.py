"""Campaign requests and controls shared by the API and the scheduler.

The API never drives hardware: it writes rows. A queued campaign (or a paused
one that no process holds a rig lease for) is moved by the API directly; a
campaign that a runner holds gets a ``requested_action`` that the runner
applies at its next safe point. Every state write is a conditional UPDATE on
the state it was read in, so a runner in another process can never be
overwritten with a stale state.

The dry run's prediction is stored with the campaign when it is created
(:func:`create_campaign`); a campaign created before the service stored it gets
it computed once, on first read, and stored (:func:`stored_prediction`). This
module speaks rows and the campaign spec, not HTTP: the API layer
(``service.api``) turns what it returns into responses.
"""

from __future__ import annotations

import functools
from typing import Any

from sqlalchemy import select, update
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from service.db.models import Campaign, Rig, RigLease, Schedule, Sensor
from service.db.timestamps import as_utc, utcnow
from service.dry_run import PlanCheck, PlanIssue, check_campaign, prediction
from service.engine.spec import CampaignCreate, EngineSpec, stored_serials
from service.engine.states import UNHELD_TARGETS, check_action
from service.engine.store import cas_transition

SIM_RIG_NAME = "sim"
SIM_CHAMBER_RANGE_C = (-70.0, 180.0)
SIM_RIG: dict[str, Any] = {
    "name": SIM_RIG_NAME,
    "chamber": {"driver": "sim", "range_c": list(SIM_CHAMBER_RANGE_C)},
    "turntable": {"driver": "sim"},
    "sensors": [{"driver": "sim", "model": "ADXL355"}],
}
ACTIVE_STATES = ("running", "paused")  # paused holds the rig only once started


class CampaignNotFound(LookupError):
    def __init__(self, campaign_id: int) -> None:
        super().__init__(f"campaign {campaign_id} not found")


def seed_sim_rig(session: Session) -> bool:
    """Insert the embedded ``sim`` rig if it is missing; True when inserted."""
    if session.scalar(select(Rig.id).where(Rig.name == SIM_RIG_NAME)) is not None:
        return False
    session.add(Rig(**SIM_RIG))
    session.flush()
    return True


def load_rigs_file(path: str) -> list[dict[str, Any]]:
    """Rig configs from a JSON file (a list of ``{"name", "chamber", "turntable", "sensors"}``).

    Raises ``ValueError`` naming the file, the rig and the field when a config
    is unusable, so the service refuses to start rather than fail at 2 a.m.
    """
    import json

    from service.engine.rigs import rig_config_errors

    try:
        with open(path, encoding="utf-8") as fh:
            doc = json.load(fh)
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the rigs file ({exc})") from exc
    if not isinstance(doc, list):
        raise ValueError(f"{path}: expected a JSON list of rigs")
    rigs: list[dict[str, Any]] = []
    for i, item in enumerate(doc):
        name = item.get("name") if isinstance(item, dict) else None
        if not isinstance(name, str) or not name:
            raise ValueError(f"{path}: rig [{i}]: missing 'name'")
        rig = {"name": name, "chamber": item.get("chamber") or {},
               "turntable": item.get("turntable") or {}, "sensors": item.get("sensors") or []}
        problems = rig_config_errors(rig["chamber"], rig["turntable"], rig["sensors"])
        if problems:
            field, why = problems[0]
            raise ValueError(f"{path}: rig {name!r}: {field}: {why}")
        rigs.append(rig)
    return rigs


def upsert_rigs(session: Session, rigs: list[dict[str, Any]]) -> list[str]:
    """Insert rigs, or update the config of idle ones; a busy rig keeps its config (logged)."""
    changed: list[str] = []
    for cfg in rigs:
        row = session.scalar(select(Rig).where(Rig.name == cfg["name"]))
        if row is None:
            session.add(Rig(**cfg))
            changed.append(cfg["name"])
        elif (row.chamber, row.turntable, row.sensors) != (
                cfg["chamber"], cfg["turntable"], cfg["sensors"]) and not rig_busy(
                session, row.name):
            row.chamber, row.turntable, row.sensors = (
                cfg["chamber"], cfg["turntable"], cfg["sensors"])
            changed.append(cfg["name"])
    session.flush()
    return changed


def plan_check(session: Session, spec: CampaignCreate) -> PlanCheck:
    """The dry run of ``spec`` on its rig (``service.dry_run``): issues and predicted duration."""
    rig = session.scalar(select(Rig).where(Rig.name == spec.rig))
    rig_cfg = None if rig is None else {
        "name": rig.name, "chamber": rig.chamber, "turntable": rig.turntable,
        "sensors": rig.sensors}
    return check_campaign(spec, rig_cfg, spec.rig)


def campaign_serials(stored: dict[str, Any], first: str) -> list[str]:
    """The sensors a stored campaign spec names, in order (``[first]`` for a one-sensor one)."""
    return list(stored_serials(stored, first)) or [first]


def rig_mounted_serials(rig_cfg: dict[str, Any]) -> set[str] | None:
    """Serials a rig declares mounted; ``None`` when any serial mounts (the ``sim`` twin).

    A real rig's sensor entry declares its sensor by ``serial``, a multiplexing bridge's
    by its ``channels``, or by the values of its ``serials`` table (board uid → serial,
    docs/api.md "Rigs"): :func:`service.engine.rigs.entry_serials`.
    """
    from service.engine.rigs import entry_serials

    if (rig_cfg.get("chamber") or {}).get("driver", "sim") == "sim":
        return None
    mounted: set[str] = set()
    for entry in rig_cfg.get("sensors") or []:
        if isinstance(entry, dict):
            mounted.update(entry_serials(entry))
    return mounted


def mount_issues(session: Session, spec: CampaignCreate) -> list[PlanIssue]:
    """A ``sensors`` entry a real rig does not mount, named (the twin mounts any).

    Only ``sensors`` is checked: a one-sensor campaign (``sensor``) on a rig whose fixture
    binds by EEPROM is verified at start by the identity check, as before.
    """
    if spec.sensors is None:
        return []
    rig = session.scalar(select(Rig).where(Rig.name == spec.rig))
    if rig is None:
        return []  # the dry run already names the unknown rig
    mounted = rig_mounted_serials({"chamber": rig.chamber, "sensors": rig.sensors})
    if mounted is None:
        return []
    return [PlanIssue(("sensors", i),
                      f"sensor {serial!r} is not mounted on rig {rig.name!r} "
                      f"(mounted: {', '.join(sorted(mounted)) or 'none declared'})", serial)
            for i, serial in enumerate(spec.sensors) if serial not in mounted]


@functools.lru_cache(maxsize=64)
def positions_count(name: str) -> int | None:
    """Number of orientations of a named schedule; None when the name is unknown."""
    from calibration.schedules import get_schedule  # numpy: only when a name is checked

    try:
        return int(len(get_schedule(name)))
    except (ValueError, KeyError):
        return None


def create_campaign(
    session: Session, spec: CampaignCreate, schedule_id: int | None = None,
    check: PlanCheck | None = None,
) -> Campaign:
    """A new ``queued`` campaign with its dry run stored (the caller checked
    :func:`plan_check` and :func:`mount_issues`; ``check``: that verdict, so the campaign
    is not planned twice); flushed, not committed."""
    for serial in spec.serials:
        ensure_sensor(session, serial)
    campaign = Campaign(
        rig=spec.rig,
        sensor=spec.serials[0],  # the first sensor: one-sensor readers keep working
        spec=spec.stored(),
        state="queued",
        schedule_id=schedule_id,
        progress={},
        steps_log=[],
        dry_run=_stored_form(check if check is not None else plan_check(session, spec)),
    )
    session.add(campaign)
    session.flush()
    return campaign


def ensure_sensor(session: Session, serial: str) -> None:
    """Get-or-create the sensor row, safe when concurrent first requests race for a serial.

    ``INSERT ... ON CONFLICT (serial) DO NOTHING`` on both PostgreSQL and SQLite: the
    loser of the race inserts nothing instead of failing on the unique constraint.
    """
    dialect = session.get_bind().dialect.name
    if dialect == "postgresql":
        from sqlalchemy.dialects.postgresql import insert
    elif dialect == "sqlite":
        from sqlalchemy.dialects.sqlite import insert
    else:  # another backend: the plain check (not race-safe)
        if session.scalar(select(Sensor.id).where(Sensor.serial == serial)) is None:
            session.add(Sensor(serial=serial))
        return
    session.execute(insert(Sensor).values(serial=serial, model="ADXL355", created_at=utcnow())
                    .on_conflict_do_nothing(index_elements=["serial"]))


def apply_action(session: Session, campaign_id: int, action: str) -> Campaign:
    """Pause, resume or abort; raises ``IllegalTransition`` (409) or ``CampaignNotFound``.

    A campaign no engine holds moves at once to the state the table gives
    (``states.UNHELD_TARGETS``); a held one gets ``requested_action``, which its
    engine applies within one device call. Both writes are conditional on the
    state read, so a racing engine or API request cannot be overwritten.
    """
    for _ in range(5):  # an engine may change the state between our read and our write
        campaign = session.get(Campaign, campaign_id, populate_existing=True)
        if campaign is None:
            raise CampaignNotFound(campaign_id)
        check_action(action, campaign.state)
        held = campaign.state == "running" or _held_by_runner(session, campaign.id)
        target = None if held else UNHELD_TARGETS[action].get(campaign.state)
        if target is not None:
            ok = cas_transition(session, campaign_id, campaign.state, target,
                                requested_action=None)
        else:
            ok = session.execute(
                update(Campaign)
                .where(Campaign.id == campaign_id, Campaign.state == campaign.state)
                .values(requested_action=action)
            ).rowcount == 1
        if ok:
            session.commit()
            refreshed = session.get(Campaign, campaign_id, populate_existing=True)
            assert refreshed is not None
            return refreshed
        session.rollback()
    raise RuntimeError(f"campaign {campaign_id} kept changing state; try again")


def _held_by_runner(session: Session, campaign_id: int) -> bool:
    lease = session.scalar(select(RigLease).where(RigLease.campaign_id == campaign_id))
    return lease is not None and (as_utc(lease.lease_until) or utcnow()) > utcnow()


def rig_busy(session: Session, rig_name: str) -> bool:
    """A campaign holds the rig: running, paused after it started, or a live lease.

    A campaign paused while still queued has not touched the rig and does not
    hold it: the other queued campaigns run (a paused queue cannot jam).
    """
    return rig_name in busy_rig_names(session, rig_name)


def busy_rig_names(session: Session, rig_name: str | None = None) -> set[str]:
    """The rigs :func:`rig_busy` calls busy (only ``rig_name`` when given): two queries for
    any number of rigs, so ``GET /rigs`` does not cost two queries per rig."""
    holding = (Campaign.state == "running") | (
        (Campaign.state == "paused") & Campaign.started_at.is_not(None))
    campaigns = select(Campaign.rig).where(holding).distinct()
    leases = select(RigLease.rig, RigLease.lease_until)
    if rig_name is not None:
        campaigns = campaigns.where(Campaign.rig == rig_name)
        leases = leases.where(RigLease.rig == rig_name)
    busy = set(session.scalars(campaigns))
    now = utcnow()
    busy.update(name for name, until in session.execute(leases)
                if until is not None and as_utc(until) > now)  # type: ignore[operator]
    return busy


def _stored_form(check: PlanCheck) -> dict[str, Any]:
    """What a row stores of a dry run: the prediction, or why there is none."""
    if check.prediction is not None:
        return dict(check.prediction)
    why = "; ".join(issue.msg for issue in check.issues) or "not predicted"
    return {"duration_s": None, "why": why}


def spec_prediction(stored: dict[str, Any]) -> dict[str, Any]:
    """The dry run of a stored campaign spec, without its rig (the door checked that):
    :func:`service.dry_run.prediction`, or ``duration_s`` None with why not."""
    import json

    known = {k: v for k, v in stored.items() if k in EngineSpec.model_fields}
    try:
        key = json.dumps(known, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        return {"duration_s": None, "why": f"the stored spec is not JSON: {exc}"}
    return dict(_prediction_of(key))


@functools.lru_cache(maxsize=256)
def _prediction_of(spec_json: str) -> dict[str, Any]:
    # Campaigns that differ only in rig or sensors share one plan (a list of campaigns
    # stored before migration 0008 is planned once per distinct spec, not once per row).
    import json

    from pydantic import ValidationError

    try:
        spec = EngineSpec.model_validate(json.loads(spec_json))
    except ValidationError as exc:
        return {"duration_s": None, "why": f"the stored spec is not valid any more: "
                f"{exc.errors()[0]['msg']}"}
    if positions_count(spec.positions) is None:
        return {"duration_s": None, "why": f"unknown position schedule {spec.positions!r}"}
    return prediction(spec)


def stored_prediction(session: Session, row: Campaign | Schedule) -> dict[str, Any]:
    """The dry run stored with a campaign or schedule; computed once and stored for a row
    created before the service stored it (a conditional UPDATE, so a racing reader's
    identical value is not written twice; a locked database only delays the store)."""
    if row.dry_run is not None:
        return dict(row.dry_run)
    spec = row.spec if isinstance(row, Campaign) else row.campaign
    predicted = spec_prediction(spec or {})
    model = type(row)
    try:
        session.execute(update(model).where(model.id == row.id, model.dry_run.is_(None))
                        .values(dry_run=predicted)
                        .execution_options(synchronize_session=False))
        session.commit()
    except OperationalError:  # a busy SQLite: the next read stores it
        session.rollback()
    return predicted


def stored_duration_s(session: Session, row: Campaign | Schedule) -> float | None:
    """The stored dry run's predicted duration, s (None: it could not be predicted)."""
    duration = stored_prediction(session, row).get("duration_s")
    return None if duration is None else float(duration)
