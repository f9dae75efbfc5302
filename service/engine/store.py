"""Everything the runner reads from and writes to the database, one short transaction each.

The runner holds no session across ``await``s: every function opens a
session, does one thing and commits, so a SIGKILL at any instant leaves the
database at a transaction boundary. The measurement insert and the cursor
move are one transaction (:func:`commit_measurements`).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from sqlalchemy import insert, select, text, update
from sqlalchemy.exc import DBAPIError, IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from calibration.table_pose import POSE_COLUMNS
from service.db.models import Calibration, Campaign, Measurement, RigLease, SoakProbe, utcnow
from service.db.timestamps import as_utc
from service.engine.calibrate import CalibrationRow
from service.engine.states import TERMINAL, TRANSITIONS
from service.event_log import log_event

SessionFactory = sessionmaker[Session]
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Control:
    """What the API (any process) asked: the campaign's state and requested action."""

    state: str
    requested_action: str | None


def load_campaign(sf: SessionFactory, campaign_id: int) -> Campaign:
    with sf() as s:
        c = s.get(Campaign, campaign_id)
        if c is None:
            raise LookupError(f"campaign {campaign_id} does not exist")
        s.expunge(c)
        return c


def read_control(sf: SessionFactory, campaign_id: int) -> Control:
    """State and requested action; read before every device call, so a bare connection
    (no ORM session: ~0.4 ms instead of ~1 ms on SQLite)."""
    with sf.kw["bind"].connect() as conn:
        row = conn.execute(
            select(Campaign.state, Campaign.requested_action).where(Campaign.id == campaign_id)
        ).one()
        return Control(state=row[0], requested_action=row[1])


def measured_positions(sf: SessionFactory, campaign_id: int) -> set[tuple[int, int]]:
    """(step, position) pairs already stored: the ground truth for resuming."""
    with sf() as s:
        rows = s.execute(
            select(Measurement.step, Measurement.position).where(
                Measurement.campaign_id == campaign_id
            )
        ).all()
        return {(int(a), int(b)) for a, b in rows}


def last_t_s(sf: SessionFactory, campaign_id: int) -> float:
    from sqlalchemy import func

    with sf() as s:
        v = s.execute(
            select(func.max(Measurement.t_s)).where(Measurement.campaign_id == campaign_id)
        ).scalar()
        return float(v or 0.0)


def transition(
    sf: SessionFactory, campaign_id: int, to_state: str, *, clear_action: bool = False,
    **fields: Any,
) -> bool:
    """Move the campaign to ``to_state`` if the table allows it from its current state.

    Reads the current state, then a conditional UPDATE on it (:func:`cas_transition`),
    so a concurrent writer (the API, another process) is never overwritten:
    returns False when the table forbids the move or the state changed under us.
    Already in ``to_state`` counts as done (True). Through :func:`fenced_sessions`, a
    process whose lease is lost writes nothing and gets False too (the state is the
    holder's to decide): never an exception that a caller could take for a failure of
    the campaign and write down unfenced.
    """
    with sf() as s:
        current = s.execute(select(Campaign.state).where(Campaign.id == campaign_id)).scalar_one()
        if current == to_state:
            return True
        values: dict[str, Any] = dict(fields)
        if clear_action:
            values["requested_action"] = None
        try:
            ok = cas_transition(s, campaign_id, current, to_state, **values)
        except LeaseLost as exc:
            _log.error("campaign %s: %s → %s not written: %s", campaign_id, current,
                       to_state, exc)
            return False
        s.commit()
    if ok:
        _log_transition(campaign_id, current, to_state, fields.get("error"))
    return ok


def _log_transition(campaign_id: int, from_state: str, to_state: str, error: Any) -> None:
    """One structured log line per state change the runner writes (service/event_log.py)."""
    if to_state == "running":
        event = "campaign started" if from_state == "queued" else "campaign resumed"
    elif to_state == "paused":
        event = "campaign paused"
    elif to_state in ("completed", "failed", "aborted"):
        event = "campaign ended"
    else:
        event = "campaign state"
    log_event(event, campaign=campaign_id, state=to_state, was=from_state, error=error)

def cas_transition(s: Session, campaign_id: int, from_state: str, to_state: str,
                   **values: Any) -> bool:
    """``UPDATE campaign SET state = to_state WHERE id = ? AND state = from_state``.

    The one way any writer (engine, API, manager) changes a campaign's state:
    the move must be in :data:`service.engine.states.TRANSITIONS`, and the
    WHERE on the expected from-state makes two concurrent writers unable to
    both win (the loser's rowcount is 0). Does not commit.
    """
    if (from_state, to_state) not in TRANSITIONS:
        return False
    values = {"state": to_state, **values}
    if to_state in TERMINAL:
        values.setdefault("finished_at", utcnow())
    res = s.execute(
        update(Campaign)
        .where(Campaign.id == campaign_id, Campaign.state == from_state)
        .values(**values)
    )
    return bool(res.rowcount == 1)


def clear_action(sf: SessionFactory, campaign_id: int, action: str) -> None:
    with sf() as s:
        s.execute(
            update(Campaign)
            .where(Campaign.id == campaign_id, Campaign.requested_action == action)
            .values(requested_action=None)
        )
        s.commit()


def update_campaign(sf: SessionFactory, campaign_id: int, **fields: Any) -> None:
    with sf() as s:
        s.execute(update(Campaign).where(Campaign.id == campaign_id).values(**fields))
        s.commit()
    if "suspended_reason" in fields:  # the guard's suspend / recover (engine/guard.py)
        reason = fields["suspended_reason"]
        if reason is None:
            log_event("campaign unsuspended", campaign=campaign_id)
        else:
            log_event("campaign suspended", campaign=campaign_id, reason=reason)


def set_cursor(sf: SessionFactory, campaign_id: int, step: int, phase: str, position: int,
               progress: dict[str, Any] | None = None) -> None:
    fields: dict[str, Any] = {
        "cursor_step": step, "cursor_phase": phase, "cursor_position": position,
    }
    if progress is not None:
        fields["progress"] = progress
    update_campaign(sf, campaign_id, **fields)


@dataclass(frozen=True)
class Fence:
    """The rig lease this process must still hold for its writes to count (a fencing token)."""

    rig: str
    owner: str


class LeaseLost(Exception):
    """A fenced write found the rig lease expired or held by another process."""


# Every statement on the lease row waits at most this long for a row lock (PostgreSQL's
# lock_timeout; SQLite's busy timeout, service/db/session.py, bounds it there).
LEASE_LOCK_TIMEOUT_S = 2.0
# A fenced transaction left open by a stalled process (SIGSTOP inside a commit) holds the
# lease row's lock; PostgreSQL ends such a session after this long idle, so a takeover waits
# for it at most this long — well inside one lease period (manager.py's lease_s, 30 s).
FENCED_IDLE_TIMEOUT_S = 5.0


def bound_lease_locks(s: Session, *, fenced: bool = False) -> None:
    """Start the caller's transaction with the lease row's lock waits bounded (PostgreSQL).

    ``fenced``: also end the session if this process stalls with the transaction open
    (``idle_in_transaction_session_timeout``), so its row lock cannot outlive the stall.
    SQLite has one writer and its busy timeout (:func:`lease_session` shortens it for the
    manager's lease statements).
    """
    if s.get_bind().dialect.name != "postgresql":
        return
    s.execute(text(f"SET LOCAL lock_timeout = '{int(LEASE_LOCK_TIMEOUT_S * 1000)}ms'"))
    if fenced:
        s.execute(text("SET LOCAL idle_in_transaction_session_timeout = "
                       f"'{int(FENCED_IDLE_TIMEOUT_S * 1000)}ms'"))


@contextlib.contextmanager
def lease_session(sf: SessionFactory) -> Iterator[Session]:
    """A session for the manager's lease statements (claim, renew, release), each of
    whose lock waits ends after :data:`LEASE_LOCK_TIMEOUT_S` with an ``OperationalError``.

    PostgreSQL: call :func:`bound_lease_locks` at the start of each transaction
    (``SET LOCAL`` lasts one). SQLite: the connection's busy timeout is shortened for
    the session and put back after it (it is the pooled connection's setting).
    """
    with sf() as s:
        sqlite = s.get_bind().dialect.name == "sqlite"
        if sqlite:
            s.execute(text(f"PRAGMA busy_timeout = {int(LEASE_LOCK_TIMEOUT_S * 1000)}"))
        try:
            yield s
        finally:
            if sqlite:
                from service.db.session import SQLITE_BUSY_TIMEOUT_MS

                with contextlib.suppress(Exception):
                    s.rollback()
                    s.execute(text(f"PRAGMA busy_timeout = {SQLITE_BUSY_TIMEOUT_MS}"))
                    s.commit()


def confirm_lease(sf: SessionFactory, fence: Fence, campaign_id: int) -> dt.datetime:
    """When this process's live lease on ``fence.rig`` for ``campaign_id`` ends (UTC);
    :class:`LeaseLost` when it holds none. A plain read (it takes no lock): the device
    fence's check before every command that changes the rig (service/engine/fencing.py)."""
    with sf.kw["bind"].connect() as conn:
        until = conn.execute(
            select(RigLease.lease_until).where(
                RigLease.rig == fence.rig, RigLease.owner == fence.owner,
                RigLease.campaign_id == campaign_id, RigLease.lease_until > utcnow())
        ).scalar()
    if until is None:
        raise LeaseLost(f"rig {fence.rig!r}: lease no longer held by {fence.owner}")
    return as_utc(until) or until


# Session.info keys: the transaction whose lease is confirmed; a confirmation under way.
_FENCED_TRANSACTION = "soakcal.fenced_transaction"
_CONFIRMING = "soakcal.confirming_lease"


def _check_fence(s: Session, fence: Fence, campaign_id: int) -> None:
    """Inside the caller's transaction: this process still holds a live lease on the rig.

    A no-op UPDATE rather than a SELECT so PostgreSQL locks the lease row until
    the commit: a takeover (a conditional UPDATE on the same row) waits for this
    transaction and then sees the lease as it is after it. The wait is bounded on
    both sides (:func:`bound_lease_locks`).
    """
    s.info[_CONFIRMING] = True  # the check's own UPDATE asks for no check (fenced_sessions)
    try:
        bound_lease_locks(s, fenced=True)
        res = s.execute(
            update(RigLease)
            .where(RigLease.rig == fence.rig, RigLease.owner == fence.owner,
                   RigLease.campaign_id == campaign_id, RigLease.lease_until > utcnow())
            .values(owner=fence.owner)
        )
    finally:
        s.info.pop(_CONFIRMING, None)
    if res.rowcount != 1:
        raise LeaseLost(f"rig {fence.rig!r}: lease no longer held by {fence.owner}")
    s.info[_FENCED_TRANSACTION] = s.get_transaction()  # begun by now: the UPDATE ran in it


def fenced_sessions(sf: SessionFactory, fence: Fence | None,
                    campaign_id: int) -> SessionFactory:
    """``sf``'s sessions, with every transaction that writes confirming the lease in itself.

    The runner's writes for a campaign (progress, cursor, soak probes, step log,
    dropped sensors, suspensions, state changes, calibrations) go through plain
    :func:`update_campaign`-like functions. Given this factory, each transaction
    that is about to write first runs :func:`_check_fence` in the same transaction
    (once per transaction): an ORM INSERT/UPDATE/DELETE statement
    (``do_orm_execute``) or a flush with pending objects (``before_flush``). A process
    whose lease is lost or cannot be confirmed (a lock wait that timed out, a session
    the server ended) gets :class:`LeaseLost` and the transaction writes nothing.
    Reads pay nothing: a SELECT and a flush with nothing pending are not checked, and
    :func:`read_control` / :func:`confirm_lease` use a bare connection. Plain-text
    SQL (``text()``) is not recognised as a write; the store writes none.
    ``fence`` None: ``sf`` itself (an unfenced runner: tests, the demo).
    """
    if fence is None:
        return sf
    from sqlalchemy import event

    fenced: SessionFactory = sessionmaker(class_=sf.class_, **sf.kw)

    def confirm(s: Session) -> None:
        if s.info.get(_CONFIRMING):
            return  # the check's own UPDATE
        tx = s.get_transaction()  # None: not begun (the write about to run begins it)
        if tx is not None and s.info.get(_FENCED_TRANSACTION) is tx:
            return  # confirmed in this transaction already (its row lock holds to the commit)
        try:
            _check_fence(s, fence, campaign_id)
        except DBAPIError as exc:
            raise LeaseLost(f"rig {fence.rig!r}: lease not confirmed "
                            f"({type(exc).__name__}: {str(exc).splitlines()[0]})") from exc

    @event.listens_for(fenced, "do_orm_execute")
    def _before_write(state: Any) -> None:
        if state.is_insert or state.is_update or state.is_delete:
            confirm(state.session)

    @event.listens_for(fenced, "before_flush")
    def _before_flush(s: Session, _context: Any, _instances: Any) -> None:
        if s.new or s.dirty or s.deleted:
            confirm(s)

    return fenced


def commit_measurements(
    sf: SessionFactory, campaign_id: int, rows: list[dict[str, Any]], step: int,
    next_position: int, progress: dict[str, Any], fence: Fence | None = None,
) -> bool:
    """Store every sensor's measurement of one position and move the cursor past it,
    atomically (one sensor: one row).

    All rows of a position and the cursor past it are one transaction, so a position
    is stored for every live sensor or for none and :func:`measured_positions` stays
    exact on resume. Returns False when (step, position) was already stored (a previous
    process committed it just before dying): that is "done", not an error. With a
    ``fence``, the same transaction verifies that this process still holds the rig's
    lease; if not, nothing is written and :class:`LeaseLost` is raised.
    """
    with sf() as s:
        try:
            if fence is not None:
                _check_fence(s, fence, campaign_id)
            # One multi-row INSERT (executemany), not one ORM object per row: the unit of
            # work's per-object bookkeeping was most of a 16-sensor position's commit. It
            # is a Session.execute, so a fenced factory's write hook confirms the lease.
            if rows:
                s.execute(insert(Measurement), [{"campaign_id": campaign_id, **row}
                                                for row in rows])
            s.execute(
                update(Campaign).where(Campaign.id == campaign_id).values(
                    cursor_step=step, cursor_phase="positions",
                    cursor_position=next_position, progress=progress,
                )
            )
            s.commit()
            return True
        except IntegrityError:
            s.rollback()
        except LeaseLost:
            s.rollback()
            raise
        except DBAPIError as exc:
            if fence is None:
                raise
            # A lock wait timed out, or the server ended this session while we stalled:
            # the lease cannot be confirmed, so this process stops writing (and commanding).
            with contextlib.suppress(Exception):
                s.rollback()
            raise LeaseLost(f"rig {fence.rig!r}: lease not confirmed "
                            f"({type(exc).__name__}: {str(exc).splitlines()[0]})") from exc
    set_cursor(sf, campaign_id, step, "positions", next_position, progress)
    return False


def drop_sensor(sf: SessionFactory, campaign_id: int, serial: str, reason: str) -> None:
    """Record that ``serial`` was dropped from the campaign (``sensors_dropped``) and log it."""
    with sf() as s:
        c = s.get(Campaign, campaign_id)
        assert c is not None
        c.sensors_dropped = {**(c.sensors_dropped or {}), serial: reason}
        s.commit()
    log_event("sensor dropped", campaign=campaign_id, sensor=serial, reason=reason)


def put_step_log(sf: SessionFactory, campaign_id: int, entry: dict[str, Any]) -> None:
    """Replace (or append) the steps_log entry of ``entry['step']``; a resumed step updates it."""
    with sf() as s:
        c = s.get(Campaign, campaign_id)
        assert c is not None
        log = [e for e in (c.steps_log or []) if e.get("step") != entry["step"]]
        log.append(entry)
        log.sort(key=lambda e: e.get("step", 0))
        c.steps_log = log
        s.commit()
    log_event(
        "soak ended", campaign=campaign_id, step=entry.get("step"),
        setpoint_c=entry.get("setpoint_c"), soak_s=entry.get("soak_s"),
        reason=entry.get("reason"),
    )


PROBE_COLUMNS = ("t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "ref_x", "ref_y",
                 "ref_z", "ax", "ay", "az", "n")


def add_soak_probes(sf: SessionFactory, campaign_id: int, rows: list[dict[str, Any]],
                    progress: dict[str, Any] | None = None) -> None:
    """Store one poll's soak probes (every sensor's) as they are taken, in one short commit;
    keys: SoakProbe's columns. ``progress``: the poll's progress, written in the same
    commit (one transaction a poll, not two: the probes and what the poll published are
    stored together or not at all).

    One multi-row INSERT (executemany), not one ORM object per row, as
    :func:`commit_measurements`: a ``Session.execute``, so a fenced factory's write hook
    confirms the lease in this transaction."""
    if not rows and progress is None:
        return
    with sf() as s:
        if rows:
            s.execute(insert(SoakProbe), [{"campaign_id": campaign_id, **row} for row in rows])
        if progress is not None:
            s.execute(update(Campaign).where(Campaign.id == campaign_id)
                      .values(progress=progress))
        s.commit()


def soak_probe_rows(sf: SessionFactory, campaign_id: int,
                    sensor: str | None = None) -> list[dict[str, Any]]:
    """The stored probes (of ``sensor`` when given) as dicts, in time order.

    Keys: ``sensor``, ``soak_start_t_s``, ``pose`` and :data:`PROBE_COLUMNS`.
    """
    names = ("sensor", "soak_start_t_s", "pose") + PROBE_COLUMNS
    with sf() as s:
        rows = s.execute(
            select(*(getattr(SoakProbe, n) for n in names))
            .where(SoakProbe.campaign_id == campaign_id,
                   *(() if sensor is None else (SoakProbe.sensor == sensor,)))
            .order_by(SoakProbe.t_s, SoakProbe.id)
        ).all()
    return [dict(zip(names, r, strict=True)) for r in rows]


def measurement_columns(sf: SessionFactory, campaign_id: int,
                        sensor: str | None = None) -> dict[str, list[float]]:
    """The stored measurements (of ``sensor`` when given) as recording-v1 columns, time order;
    the commanded poses (``pose_q*``, docs/recording.md) where any row has one."""
    names = ("t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position", "ref_x", "ref_y",
             "ref_z", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z", *POSE_COLUMNS)
    with sf() as s:
        rows = s.execute(
            select(*(getattr(Measurement, n) for n in names))
            .where(Measurement.campaign_id == campaign_id,
                   *(() if sensor is None else (Measurement.sensor == sensor,)))
            .order_by(Measurement.t_s, Measurement.step, Measurement.position)
        ).all()
    cols: dict[str, list[float]] = {n: [] for n in names}
    for r in rows:
        for n, v in zip(names, r, strict=True):
            cols[n].append(float("nan") if v is None else float(v))
    if all(math.isnan(v) for c in POSE_COLUMNS for v in cols[c]):
        for c in POSE_COLUMNS:  # no pose recorded (a hand-placed fixture): no columns
            del cols[c]
    return cols


def store_calibration(sf: SessionFactory, campaign_id: int, values: CalibrationRow,
                      sensor: str | None = None) -> int:
    """Insert the Calibration row (``values.columns()``) and link it from the campaign in
    one transaction.

    ``sensor`` (several-sensor campaigns): the row is that sensor's and is linked in
    ``calibration_ids``; ``calibration_id`` is set for the campaign's first sensor.
    """
    with sf() as s:
        c = s.get(Campaign, campaign_id)
        assert c is not None
        if sensor is None:
            if c.calibration_id is not None:  # a previous process got this far before dying
                return c.calibration_id
        elif sensor in (c.calibration_ids or {}):
            return int((c.calibration_ids or {})[sensor])
        serial = c.sensor if sensor is None else sensor
        cal = Calibration(campaign_id=campaign_id, sensor=serial, **values.columns())
        s.add(cal)
        s.flush()
        if sensor is None or sensor == c.sensor:
            c.calibration_id = cal.id
        if sensor is not None:
            c.calibration_ids = {**(c.calibration_ids or {}), sensor: cal.id}
        s.commit()
        return cal.id


def now_utc() -> dt.datetime:
    return utcnow()


def fast_sqlite_commits(sf: SessionFactory) -> None:
    """WAL + ``synchronous=NORMAL`` on an SQLite engine (no-op for other databases).

    A commit then survives the *process* being killed (SIGKILL: what the crash
    tests and the demo care about) but not a power cut, and costs ~0.1 ms
    instead of an fsync. The service keeps SQLite's default (FULL).
    """
    from sqlalchemy import event

    engine = sf.kw["bind"]
    if engine.dialect.name != "sqlite":
        return

    def _pragma(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
        cur = dbapi_connection.cursor()
        cur.execute("PRAGMA synchronous=NORMAL")
        cur.close()

    event.listen(engine, "connect", _pragma)
    engine.dispose()  # connections opened before now would keep FULL
