"""The campaign engine: the message loop that runs a plan (calibration/campaign_plan.py)
over a persisted cursor.

The plan is the protocol (ramp, soak, the sweep of positions, the retake of a
capture off its pose); the engine executes its verbs, one handler each, and
owns what no plan should: checkpoints (pause, abort), the one hold loop of
the suspenders and the rewind after it, progress and its subscribers, the
commit of each save, and the one ``finally`` that parks the rig.

Crash safety rests on one rule: a measurement row and the cursor move past it
are committed in one transaction *before the table moves again*. On start the
runner reads the measurements table (the ground truth, not the cursor) and
runs the plan with what is stored as ``done``: every (step, position) already
stored is skipped; a step with some positions measured is re-ramped
(idempotent) and re-soaked with a short re-check, because the chamber may
have drifted while nobody ran it. A suspension is the same replay: after a
chamber suspender's hold, the plan resumes from what is stored. The
database's UNIQUE(campaign_id, step, position) turns a duplicate insert into
"already stored".
"""

from __future__ import annotations

import asyncio
import datetime as dt
import functools
import logging
import math
from collections.abc import Awaitable, Callable, Iterable, Sequence
from typing import Any

import numpy as np

from calibration.campaign_plan import (
    RETAKE,
    Acquire,
    Checkpoint,
    Configure,
    Fit,
    Home,
    Move,
    Msg,
    Poll,
    PollChamber,
    PollSoak,
    ReadChamber,
    Save,
    SetChamber,
    Settle,
    Wait,
    WaitChamber,
    WaitStable,
    campaign_plan,
    soak_until_stable,
    wait_for_chamber,
)
from calibration.placement import MAX_ANGLE_DEG, check_pose
from calibration.table_pose import POSE_COLUMNS, pose_rows
from drivers.clock import Clock
from drivers.protocols import Acquisition, ChamberStatus
from service.engine import polls, rate_gain, store
from service.engine.calibrate import CalibrationRow, calibrate_columns
from service.engine.fencing import fence_devices
from service.engine.guard import (
    AbortRequested,
    CampaignFailed,
    DeviceGuard,
    FaultPolicy,
    clock_speed,
    hold,
)
from service.engine.identity import verify_sensor
from service.engine.park import PARKED_DEVICES, park_rig, parked
from service.engine.progress import (
    EtaModel,
    EtaSubscriber,
    Subscriber,
    chamber_moving_rate_c_per_min,
)
from service.engine.quality import check_acquisition
from service.engine.ramp import RampProgress
from service.engine.rigs import RigDevices
from service.engine.sensors import SensorDropped, read_all, reading_problem
from service.engine.spec import parse_spec, schedule_refs
from service.engine.states import TERMINAL
from service.engine.suspenders import Suspender, Suspenders, table_not_in_position

Calibrate = Callable[[dict[str, list[float]], dict[str, Any]], CalibrationRow]
StepReporter = Callable[[dict[str, Any]], None]
# The plan a campaign runs: (spec, refs, done, *, sensors, angles_deg) → a plan generator
# (calibration.campaign_plan.campaign_plan's signature); called again with what is stored
# after a hold (a rewind) and on every restart.
PlanFactory = Callable[..., Any]
# The plan of each campaign method (spec ``method``); a campaign's own ``plan=`` wins.
PLANS: dict[str, PlanFactory] = {"soak": campaign_plan}
TURNTABLE_POLL_S = 1.0
HOLD_POLL_S = 30.0  # chamber poll while a suspender holds the campaign, clock s
ABORT_CHECK_S = 60.0  # longest wait between two abort checks, clock s
ABORT_READ_EVERY_S = 0.05  # the guard's pre-call abort read, at most this often (loop time)
POSE_ATTEMPTS = 3  # captures of one position off its pose before the campaign fails
LEASE_LOST_REPORT = "not sent: lease lost"
log = logging.getLogger(__name__)


class CampaignRunner:
    """Runs one campaign on one rig's devices until it completes, fails or is aborted."""

    def __init__(
        self,
        session_factory: store.SessionFactory,
        campaign_id: int,
        devices: RigDevices,
        clock: Clock,
        *,
        calibrate: Calibrate = calibrate_columns,
        plan: PlanFactory | None = None,
        on_step: StepReporter | None = None,
        fence: store.Fence | None = None,
    ) -> None:
        self.sf = store.fenced_sessions(session_factory, fence, campaign_id)  # fenced writes
        self.id = campaign_id
        # Fenced: every command that changes the rig first confirms the lease (fencing.py).
        self.dev = devices if fence is None else fence_devices(devices, self._confirm_lease)
        self.clock = clock
        self.calibrate = calibrate
        self.plan = plan
        self.on_step = on_step
        # Every measurement commit and every rig command checks this lease (manager-run).
        self.fence = fence
        self.fit_result: Any = None  # the core's fit object, for the demo's report
        self._progress: dict[str, Any] = {}
        # Called with (message, started_s, ended_s) for every plan message executed.
        self._subscribers: list[Subscriber] = []
        self.suspension_log: list[dict[str, Any]] = []  # every hold: suspender, when, how long
        self._pose_attempts: dict[tuple[int, int], int] = {}  # captures off their pose
        # Finished (or interrupted) soaks' probes per sensor, for the measured rate gain
        # (rate_gain.py); reloaded from the soak_probes table on resume.
        self.rate_book = rate_gain.RateGainBook(False, 0, {})
        self._pose = "unknown"  # the table's commanded angles, the probes' orientation key
        self._pose_ref: tuple[float, float, float] | None = None
        # The pose the table was commanded to for a position: ((step, position), its
        # quaternion or None), recorded with the position's readings (:meth:`_commit`).
        self._position_pose: tuple[tuple[int, int], tuple[float, ...] | None] | None = None
        self._abort_checked_s = -math.inf
        # Every capture found off its pose and measured again (step, position, attempt, angle).
        self.pose_log: list[dict[str, Any]] = []
        # The last die reading (clock s, median die °C): a die still approaching the air
        # explains a gap to the PV, a settled one does not (_check_die_against_chamber).
        self._die_track: tuple[float, float] | None = None
        # The chamber's last PV at a capture (clock s, °C): how fast the air itself moves.
        self._pv_track: tuple[float, float] | None = None
        # Clock time the campaign stood still (paused or suspended): never soak time, never
        # a ramp's, never in the ETA's measured durations (:meth:`_held_total_s`).
        self._held_s = 0.0
        self._held_since_s: float | None = None
        self._paused_s = 0.0  # of which paused by the operator (not a suspender's time)
        self._ramp: RampProgress | None = None  # a ramp campaign's plan (service/engine/ramp.py)

    def _confirm_lease(self) -> dt.datetime:
        """The device fence's check (fencing.py): when the lease ends, or
        :class:`store.LeaseLost` when it is not held."""
        assert self.fence is not None
        return store.confirm_lease(self.sf, self.fence, self.id)

    def subscribe(self, fn: Subscriber) -> None:
        """Call ``fn(message, started_s, ended_s)`` after each plan message is executed."""
        self._subscribers.append(fn)

    # --- the plan ---------------------------------------------------------
    async def run(self) -> str:
        """Execute (or resume) the campaign; returns its final state.

        Every exit goes through one ``finally`` that drives the rig to its safe
        state (:meth:`_drive_safe`) once the rig was touched: completion, abort,
        failure, an exception no one expected (a device layer's ``UnicodeError``),
        and a cancellation (service shutdown, or the manager cancelling us after
        losing the rig lease). Only then is the terminal state written, so
        "aborted"/"failed"/"completed" in the database means "the rig is safe".
        A cancelled campaign stays ``running`` for the next lease holder.
        """
        camp = store.load_campaign(self.sf, self.id)
        if camp.state in TERMINAL:
            return camp.state
        self._touched = False
        outcome: tuple[str, dict[str, Any]] | None = None
        cancelled: asyncio.CancelledError | None = None
        lost: store.LeaseLost | None = None
        try:
            if not self._start(camp):
                return store.read_control(self.sf, self.id).state
            await self._execute(camp)
            outcome = ("completed", {"progress": {**self._progress, "phase": "fitting",
                                                  "fraction": 1.0, "eta_s": 0.0,
                                                  "eta_wall_s": 0.0}})
        except AbortRequested:
            outcome = ("aborted", {})
        except CampaignFailed as exc:
            outcome = ("failed", {"error": str(exc)})
        except store.LeaseLost as exc:
            # Another process holds the rig now: write nothing more, park, leave the state.
            log.error("campaign %s: %s; stopping", self.id, exc)
            lost = exc
        except asyncio.CancelledError as exc:
            cancelled = exc
            task = asyncio.current_task()
            if task is not None:  # let the safe-state calls run (and their socket I/O)
                task.uncancel()
        except Exception as exc:  # an engine or device-layer bug: fail, never leave it running
            log.exception("campaign %s: unexpected error", self.id)
            outcome = ("failed", {"error": f"engine error: {type(exc).__name__}: {exc}"})
        finally:
            if self._touched and lost is None:
                cancelled = await self._park_through_cancel() or cancelled
            elif self._touched:
                # The rig is another process's now: parking it would move the table and the
                # setpoint under the new holder's measurement. It parks when it is done.
                log.error("campaign %s: rig not parked: the lease is lost", self.id)
                self.safe_report = dict.fromkeys(PARKED_DEVICES, LEASE_LOST_REPORT)
        if cancelled is not None:
            raise cancelled
        if lost is None and outcome is not None and self.fence is not None:
            try:  # a terminal state is a write like a measurement: only the holder's counts
                self._confirm_lease()
            except store.LeaseLost as exc:
                log.error("campaign %s: %s; leaving its state to the holder", self.id, exc)
                lost = exc
        if lost is not None:
            return store.read_control(self.sf, self.id).state
        assert outcome is not None
        state, fields = outcome
        if not store.transition(self.sf, self.id, state, clear_action=True, **fields):
            return store.read_control(self.sf, self.id).state  # someone else decided first
        return state

    def _start(self, camp: Any) -> bool:
        """Parse the spec, build the guard, move ``queued → running``; False: not ours to run."""
        try:
            self.spec = spec = parse_spec(camp.spec)
        except (ValueError, TypeError, KeyError) as exc:
            raise CampaignFailed(f"spec: {exc}") from exc
        if self.plan is None:
            method = spec.method
            if method == "ramp":  # its plan resumes from the store and the rig (engine/ramp.py)
                self._ramp = RampProgress(self)
                self.plan = self._ramp.plan
            elif method not in PLANS:
                raise CampaignFailed(f"spec: method {method!r}: this engine runs "
                                     f"{', '.join([*PLANS, 'ramp'])}")
            else:
                self.plan = PLANS[method]
        self.sensor_serial = str(camp.sensor)
        # The campaign's sensors, one or several (issue 12; the spec's typed list): each
        # read at every position, dropped alone on a fault while another still reads.
        self.serials: list[str] = (list(spec.sensors) if len(spec.sensors) > 1
                                   else [self.sensor_serial])
        self.dropped: dict[str, str] = dict(camp.sensors_dropped or {})
        self.identities: dict[str, dict[str, Any]] = {}
        self.refs = schedule_refs(spec.positions)
        self.n_pos = len(self.refs)
        self.guard = DeviceGuard(
            self.clock,
            FaultPolicy(spec.retry_attempts, spec.retry_backoff_s, spec.suspend_poll_s,
                        spec.suspend_limit_s),
            on_suspend=self._suspend, on_resume=self._unsuspend,
            check_abort=self._abort_asked_recently,
        )
        self.suspenders = Suspenders(band_c=spec.chamber_band_c, limit_s=spec.suspend_limit_s,
                                     clear_s=spec.suspend_clear_s)
        if camp.state == "queued":
            return store.transition(self.sf, self.id, "running", started_at=camp.started_at
                                    or store.now_utc(),
                                    t0_s=camp.t0_s if camp.t0_s is not None else 0.0)
        return camp.state == "running"

    async def _execute(self, camp: Any) -> None:
        spec = self.spec
        done = store.measured_positions(self.sf, self.id)
        self.eta = EtaModel.for_spec(spec, self.n_pos, n_done=len(done), rate_c_per_min=(
            chamber_moving_rate_c_per_min(self.dev.chamber, spec.ramp_c_per_min)))
        self._cursor: tuple[int, str] | None = None
        # t_s continues where the stored campaign stopped (a new process has a new clock).
        self._t_base_s = max(store.last_t_s(self.sf, self.id), float(camp.progress.get("t_s", 0.0)
                                                                      if camp.progress else 0.0))
        self._clock0_s = self.clock.now()
        self._touched = True
        self._subscribers.append(EtaSubscriber(self.eta))
        self.rate_book = rate_gain.RateGainBook.from_rows(
            store.soak_probe_rows(self.sf, self.id), measured=spec.rate_gain == "measured",
            n_steps=spec.n_steps, tol_c=spec.stability.tol_c)
        if len(self.serials) > 1:
            missing = [s for s in self.serials if s not in self.dev.accelerometers]
            if missing:
                raise CampaignFailed(f"rig has no sensor {', '.join(missing)} mounted "
                                     f"(mounted: {', '.join(self.dev.accelerometers) or 'one'})")
        # The table's pose of each position, by this rig's geometry: the travel order's costs.
        angles_deg = np.array([self.dev.angles_for(r) for r in self.refs], float)
        assert self.plan is not None  # chosen by _start
        while True:
            plan = self.plan(spec, self.refs, done, sensors=self.serials,
                             angles_deg=angles_deg)
            try:
                await self._run_plan(plan)
                return
            except Rewind as rewind:
                # A suspension is a rewind: the plan resumes from what is stored, as after
                # a restart (the step re-ramped, re-soaked where the physics needs it,
                # its missing positions measured), and every subscriber sees it.
                log.info("campaign %s: %s; the plan resumes from its stored measurements",
                         self.id, rewind)
                done = store.measured_positions(self.sf, self.id)

    async def _run_plan(self, plan: Any) -> None:
        reply: Any = None
        while True:
            try:
                msg = plan.send(reply)
            except StopIteration:
                return
            reply = await self._interpret(msg)

    async def _interpret(self, msg: Msg) -> Any:
        """Execute one plan message; subscribers hear of it once it is done.

        A ``Save`` is committed here, with the cursor past it (the crash rule), and
        announced *before* its commit (the reading is complete), so the progress
        committed with it already counts it; a capture sent back to be taken again
        (:data:`RETAKE`) is neither announced nor stored.
        """
        started_s = self._active_s()
        result = await self._handlers[type(msg)](msg)
        if isinstance(msg, Save):
            if result == RETAKE:
                return RETAKE
            self._notify(msg, started_s)
            self._commit(msg, *result)
            return None
        self._notify(msg, started_s)
        return result

    def _held_total_s(self) -> float:
        """Clock time held (paused or suspended) so far, an ongoing hold included."""
        ongoing_s = 0.0 if self._held_since_s is None else self.clock.now() - self._held_since_s
        return self._held_s + ongoing_s

    def _active_s(self) -> float:
        """The clock without the held time: subscribers' (the ETA's) durations exclude it."""
        return self.clock.now() - self._held_total_s()

    def _notify(self, msg: Msg, started_s: float) -> None:
        for sub in self._subscribers:
            sub(msg, started_s, self._active_s())

    @property
    def _handlers(self) -> dict[type, Callable[[Any], Awaitable[Any]]]:
        return {
            Configure: self._configure, Checkpoint: self._at_checkpoint,
            SetChamber: self._set_chamber, WaitChamber: self._wait_chamber,
            ReadChamber: self._read_chamber, Home: self._home, WaitStable: self._soak,
            Move: self._move, Settle: self._settle, Acquire: self._acquire_msg,
            Save: self._save, Fit: self._fit, Wait: self._wait_msg,
            PollChamber: self._poll_chamber, PollSoak: self._poll_soak,
        }

    # --- the campaign's sensors, one or several (service/engine/sensors.py) -------------
    @property
    def _live(self) -> list[str]:
        return [s for s in self.serials if s not in self.dropped]

    def _accelerometer(self, serial: str) -> Any:
        """A several-sensor rig's sensor by serial; a one-sensor rig's one accelerometer."""
        return self.dev.accelerometers.get(serial, self.dev.accelerometer)

    def _drop(self, exc: SensorDropped) -> None:
        """Flag and drop one sensor with its reason; the campaign fails only with none left.

        A one-sensor campaign fails with the reason itself: its sensor is the campaign.
        """
        if len(self.serials) == 1:
            raise CampaignFailed(exc.reason) from exc
        self.dropped[exc.serial] = exc.reason
        store.drop_sensor(self.sf, self.id, exc.serial, exc.reason)
        if not self._live:
            reasons = "; ".join(f"{s}: {r}" for s, r in self.dropped.items())
            raise CampaignFailed(f"every sensor dropped: {reasons}")

    async def _sensor_call(self, serial: str, label: str,
                           fn: Callable[[], Awaitable[Any]]) -> Any:
        """One sensor's call under the guard's one retry policy: while another sensor still
        reads, a sensor that fails for good or outlasts its retries is given up
        (:class:`SensorDropped`); the last one left suspends or fails the campaign."""
        if len(self.serials) > 1:  # name the sensor where there is more than one
            label = f"{label} [{serial}]"
        if len(self._live) == 1:
            return await self.guard.call(label, fn)
        return await self.guard.call(label, fn,
                                     give_up=lambda why: SensorDropped(serial, why))

    async def _configure(self, msg: Configure) -> None:
        """Identity and configuration of every sensor; a failing one is dropped.

        Before any reading: the sensor connected must be the one the campaign names
        (a typo must not store a calibration under the wrong part). A mismatch is a
        configuration fault, named with both serials.
        """
        for serial in self._live:
            acc = self._accelerometer(serial)
            binding = self.dev.bindings.get(serial, self.dev.serial_binding)
            try:
                if serial not in self.identities:
                    verified = await self._sensor_call(
                        serial, "sensor.identify",
                        functools.partial(verify_sensor, acc, serial, binding))
                    self.identities[serial] = verified.as_dict()
                await self._sensor_call(serial, "accelerometer.configure",
                                        functools.partial(acc.configure, msg.range_g,
                                                          msg.odr_hz))
            except SensorDropped as exc:
                self._drop(exc)

    async def _measure_one(self, serial: str, n: int) -> tuple[Acquisition, list[str], int]:
        """Acquire; on a failed quality check measure once more and keep the second capture.
        A reading out of range for a static sensor: :class:`SensorDropped`."""
        acquire = functools.partial(self._accelerometer(serial).acquire, n)
        attempts = 1
        acq = await self._sensor_call(serial, "accelerometer.acquire", acquire)
        flags = check_acquisition(acq, n, self.spec.quality)
        if flags:
            attempts = 2
            acq = await self._sensor_call(serial, "accelerometer.acquire", acquire)
            flags = check_acquisition(acq, n, self.spec.quality)
        problem = reading_problem(acq, self.spec.range_g)
        if problem is not None:
            raise SensorDropped(serial, problem)
        return acq, flags, attempts

    async def _measure(self, n: int, serials: Sequence[str]) -> dict[str, Any]:
        """Every live sensor of ``serials`` read at once (:func:`sensors.read_all`); the
        ones that fail are dropped after all have answered (a drop may fail the campaign)."""
        return await self._read_live(serials, lambda serial: self._measure_one(serial, n))

    async def _read_live(self, serials: Iterable[str],
                         read: Callable[[str], Awaitable[Any]]) -> dict[str, Any]:
        """``read`` every live sensor of ``serials`` at once; the ones that raised
        :class:`SensorDropped` are dropped once all have answered, the rest returned."""
        got = await read_all([s for s in serials if s not in self.dropped], read)
        out: dict[str, Any] = {}
        for serial, result in got.items():
            if isinstance(result, SensorDropped):
                self._drop(result)
            else:
                out[serial] = result
        return out

    async def _at_checkpoint(self, _msg: Checkpoint) -> None:
        await self._checkpoint()

    async def _move(self, msg: Move) -> None:
        if self._cursor != (msg.step, "positions"):  # first position of this step's sweep
            store.set_cursor(self.sf, self.id, msg.step, "positions", msg.position)
            self._cursor = (msg.step, "positions")
        angles = self.dev.angles_for(np.asarray(msg.ref_g))
        await self._move_to(angles)
        self._position_pose = ((msg.step, msg.position), self._pose_quaternion(angles))

    def _pose_quaternion(self, angles_deg: tuple[float, ...]) -> tuple[float, ...] | None:
        """The commanded pose's quaternion by the rig's geometry (``RigDevices.pose_for``);
        None where the rig does not know it (a hand-placed fixture) or its geometry does
        not cover these angles."""
        pose_for = getattr(self.dev, "pose_for", None)
        if pose_for is None:
            return None
        try:
            return tuple(float(v) for v in pose_for(tuple(angles_deg)))
        except ValueError:  # a table geometry the convention does not cover
            return None

    def _pose_columns(self, step: int, position: int) -> dict[str, float | None]:
        """``pose_q*`` of the reading of (step, position): the quaternion of the move made
        for exactly this position (docs/recording.md), else empty: a capture whose
        commanded angles are not known exactly gets no pose rather than a guessed one."""
        known = self._position_pose
        q = known[1] if known is not None and known[0] == (step, position) else None
        return dict(zip(POSE_COLUMNS, q if q is not None else (None,) * 4, strict=True))

    async def _settle(self, msg: Settle) -> None:
        await self._wait(msg.settle_s)

    async def _wait_msg(self, msg: Wait) -> None:
        await self._wait(msg.seconds)

    async def _home(self, _msg: Home) -> None:
        await self._move_to(tuple(0.0 for _ in range(self.dev.turntable.n_axes)))

    async def _read_chamber(self, _msg: ReadChamber) -> ChamberStatus:
        return await self._chamber()

    async def _acquire_msg(self, msg: Acquire) -> Any:
        got = await self._measure(msg.n_samples, msg.sensors)
        return {serial: got.get(serial) for serial in msg.sensors}

    async def _fit(self, _msg: Fit) -> None:
        await self._fitting()

    async def _save(self, msg: Save) -> tuple[ChamberStatus, dict[str, Any]] | str:
        """Check a position's readings before they are stored: (chamber status, readings)
        for :meth:`_commit`, or :data:`RETAKE`.

        The chamber first (alarms; its PV in band of the setpoint unless ``msg.band`` is
        off): a reading taken while it misbehaved is discarded, the campaign holds
        (:meth:`_hold`) and the plan rewinds (:class:`Rewind`): the step is re-soaked
        where the physics needs it and the position measured again, as after a restart.

        Then every reading at its pose. A capture that does not read gravity from the
        direction its position claims (placement.check_pose: a table that reported
        in-position somewhere else) is never stored under that label: the plan measures
        the position again (:data:`RETAKE`), up to ``POSE_ATTEMPTS`` captures in all.
        Then the campaign fails naming the position and the angle; with several
        sensors, only the ones still off are dropped while another reads the pose right
        (its mount, not the table, is wrong).
        """
        readings = {s: r for s, r in dict(msg.acquisition).items()
                    if r is not None and s not in self.dropped}
        status = await self._chamber()
        band_c = msg.setpoint_c if msg.band else None  # a ramp's air is off the setpoint
        tripped = self.suspenders.check_chamber(status, band_c)
        if tripped is not None:
            await self._hold_chamber(*tripped, setpoint_c=band_c)
            raise Rewind(f"step {msg.step} position {msg.position}: {tripped[0].name}")
        off = {serial: check_pose(r[0].mean_g, msg.ref_g) for serial, r in readings.items()}
        off = {serial: c for serial, c in off.items() if not c.ok}
        if off:
            key = (msg.step, msg.position)
            attempt = self._pose_attempts[key] = self._pose_attempts.get(key, 0) + 1
            worst = max(c.angle_deg for c in off.values())
            where = (f"step {msg.step} ({msg.setpoint_c:g} °C) position {msg.position} "
                     f"(reference {_ref_text(msg.ref_g)}, table at {self._pose} deg)")
            self.pose_log.append({"step": msg.step, "position": msg.position,
                                  "attempt": attempt, "angle_deg": round(worst, 2),
                                  "sensors": sorted(off)})
            log.warning("campaign %s: %s: capture %.1f° from its reference, measuring again",
                        self.id, where, worst)
            if attempt < POSE_ATTEMPTS:
                return RETAKE
            if len(off) == len(readings):
                raise CampaignFailed(
                    f"{where}: the capture reads gravity {worst:.0f}° from its reference "
                    f"(limit {MAX_ANGLE_DEG:.0f}°) after {POSE_ATTEMPTS} moves to it; the table "
                    "does not stand where it reports: check its homing and encoders")
            for serial, c in off.items():
                self._drop(SensorDropped(serial, f"{where}: reads gravity {c.angle_deg:.0f}° "
                                         f"from its reference (limit {MAX_ANGLE_DEG:.0f}°): "
                                         "check its mount"))
        readings = {s: r for s, r in readings.items() if s not in self.dropped}
        if not readings:
            raise CampaignFailed(f"step {msg.step} position {msg.position}: no sensor read")
        self._check_die_against_chamber(msg, status, readings)
        return status, readings

    def _check_die_against_chamber(self, msg: Save, status: ChamberStatus,
                                   readings: dict[str, Any]) -> None:
        """Refuse to store a capture whose dies disagree with the chamber's PV where no lag
        explains it (:func:`polls.die_against_chamber`): it would label every capture of
        the step with a wrong temperature, so the campaign fails before it is stored."""
        now = self.clock.now()
        self._die_track, problem = polls.die_against_chamber(
            self._die_track, now,
            [r[0].sensor_c for r in readings.values() if r is not None], status.process_c,
            pv_before=self._pv_track)
        if math.isfinite(status.process_c):
            self._pv_track = (now, status.process_c)
        if problem is not None:
            raise CampaignFailed(f"step {msg.step} ({msg.setpoint_c:g} °C) position "
                                 f"{msg.position}: {problem}")

    def _commit(self, msg: Save, status: ChamberStatus, readings: dict[str, Any]) -> None:
        """Commit every live sensor's reading of a position and the cursor past it in one
        transaction (the crash rule)."""
        pose = self._pose_columns(msg.step, msg.position)
        ref = commanded_reference(msg.ref_g, pose)
        rows = []
        for serial in msg.sensors:
            if serial not in readings:
                continue
            acq, flags, attempts = readings[serial]
            rows.append({
                "step": msg.step, "position": msg.position,
                "t_s": self._t(self.clock.now() - acq.duration_s / 2.0),
                "setpoint_c": msg.setpoint_c, "chamber_c": status.process_c,
                "sensor_c": acq.sensor_c, "ref_x": ref[0], "ref_y": ref[1], "ref_z": ref[2],
                "ax": acq.mean_g[0], "ay": acq.mean_g[1], "az": acq.mean_g[2],
                "sd_x": acq.sd_g[0], "sd_y": acq.sd_g[1], "sd_z": acq.sd_g[2], "n": acq.n,
                "attempts": attempts, "flags": ",".join(flags) or None, "sensor": serial,
                **pose,
            })
        progress = self._publish(msg.step, "positions", msg.position, status, msg.setpoint_c,
                                 write=False)
        store.commit_measurements(self.sf, self.id, rows, msg.step, msg.next_position,
                                  progress, fence=self.fence)
        self._pose_attempts.pop((msg.step, msg.position), None)

    # --- phases -------------------------------------------------------------
    async def _set_chamber(self, msg: SetChamber) -> None:
        """Command the ramp rate and the setpoint and run the controller (no waiting)."""
        store.set_cursor(self.sf, self.id, msg.step, "ramp", 0)
        self._cursor = (msg.step, "ramp")
        ch = self.dev.chamber
        await self.guard.call("chamber.set_ramp_rate",
                              lambda: ch.set_ramp_rate(msg.ramp_c_per_min))
        await self.guard.call("chamber.set_setpoint", lambda: ch.set_setpoint(msg.setpoint_c))
        await self.guard.call("chamber.run", ch.run)

    async def _wait_chamber(self, msg: WaitChamber) -> None:
        """Wait until the working setpoint (where the controller has one) and the PV
        reach the setpoint (the plan's :func:`wait_for_chamber`); an alarm meanwhile
        holds, then rewinds (re-ramps). Bounded by twice the nominal ramp and a max soak.

        With the rate gain measured, the dies are probed during the ramp too (at home,
        like the soaks): the die's rate is large then, and the first ramp with the first
        soak measures k during that soak instead of after it
        (rate_gain.estimate_rate_gain).
        """
        spec = self.spec
        self._ramping = polls.RampState(start_s=self.clock.now(), held0_s=self._held_total_s(),
                              dies=self._no_dies(),
                              probe=(spec.rate_gain == "measured"
                                     and spec.stability.policy == "predictive"))
        try:
            await self._run_plan(wait_for_chamber(msg))
        finally:
            self.rate_book.keep(self._pose, self._ramping.dies, ramp=True)

    async def _poll_chamber(self, msg: PollChamber) -> Poll:
        spec, ramp, target_c = self.spec, self._ramping, msg.setpoint_c
        status = await self._chamber()
        tripped = self.suspenders.check_chamber(status, None)
        if tripped is not None:
            await self._hold_chamber(*tripped, setpoint_c=None)
            raise Rewind(f"step {msg.step} ramp: {tripped[0].name}")
        if polls.chamber_arrived(status, target_c, spec.stability.tol_c):
            return Poll(True)
        if ramp.limit_s is None:
            ramp.limit_s, ramp.limit_basis = polls.ramp_limit_s(
                status.process_c - target_c,
                chamber_moving_rate_c_per_min(self.dev.chamber, spec.ramp_c_per_min),
                spec.stability.max_soak_s)
        if polls.active_s(self.clock.now(), ramp.start_s, self._held_total_s(),
                          ramp.held0_s) > ramp.limit_s:
            raise CampaignFailed(f"chamber did not reach {target_c:.1f} °C within "
                                 f"{ramp.limit_s:.0f} s (PV {status.process_c:.2f} °C; "
                                 f"limit: {ramp.limit_basis})")
        polled_s = self.clock.now()
        probes = (await self._probe_dies(ramp.dies, msg.step, target_c, status,
                                         self._t(ramp.start_s)) if ramp.probe else [])
        self._publish(msg.step, "ramp", 0, status, target_c, probes=probes)
        # The probe's capture (≈ 4 s) is part of the poll period, not added to it: the
        # ramp's end is seen as soon as without probes.
        return Poll(False, spec.soak_poll_s - (self.clock.now() - polled_s))

    async def _soak(self, msg: WaitStable) -> None:
        """Wait for stability (policy of the spec; the plan's :func:`soak_until_stable`);
        log the decision in steps_log.

        The predictive policy judges the die against the sweep that follows: its
        duration (positions left × the measured time per position) and whether
        this step is the coldest or hottest (it then sets the model's valid range).
        A chamber suspender tripped meanwhile holds, then rewinds (a fresh soak).
        """
        spec, step, target_c = self.spec, msg.step, msg.setpoint_c
        # A resumed step was soaked before the interruption: re-checked, not re-soaked.
        cfg = polls.recheck_config(spec.stability, msg.resumed)
        store.set_cursor(self.sf, self.id, step, "soak", 0)
        self._cursor = (step, "soak")
        # held time before this soak is not this soak's
        soak = self._soaking = polls.SoakState(cfg, msg.n_positions * self.eta.position_s,
                                     self.clock.now(), self._held_total_s(), self._no_dies())
        await self._run_plan(soak_until_stable(msg))
        self.rate_book.keep(self._pose, soak.dies)
        self._die_track = polls.die_track_of(soak.dies) or self._die_track
        self._pv_track = None  # the air stood at its setpoint: its rate is nought, as before
        held_s = self._held_total_s() - soak.held0_s
        soak_s = polls.active_s(self.clock.now(), soak.start_s, self._held_total_s(),
                                soak.held0_s)
        entry = polls.soak_log_entry(
            soak, step=step, setpoint_c=target_c, start_t_s=self._t(soak.start_s),
            end_t_s=self._t(self.clock.now()), soak_s=soak_s, held_s=held_s, edge=msg.edge,
            resumed=msg.resumed)
        store.put_step_log(self.sf, self.id, polls.clean_json(entry))
        if self.on_step:
            self.on_step({**entry, "chamber_c": soak.ch_pv[-1], "steps": spec.n_steps})
        if soak.decision.max_soak_reached and spec.on_max_soak == "fail":
            raise CampaignFailed(
                f"step {step} ({target_c:.1f} °C) not stable after max soak {cfg.max_soak_s:.0f} s")

    async def _poll_soak(self, msg: PollSoak) -> Poll:
        """One soak poll: the chamber (a suspender tripped: hold, then rewind), the dies'
        probes, and every live die's decision (:func:`polls.decide_round`)."""
        spec, soak = self.spec, self._soaking
        step, target_c = msg.soak.step, msg.soak.setpoint_c
        status = await self._chamber()
        tripped = self.suspenders.check_chamber(status, target_c)
        if tripped is not None:
            # The die was disturbed: hold until the chamber is back, then the plan rewinds
            # and soaks afresh (the probes so far are still an approach: they stay for the
            # rate gain).
            self.rate_book.keep(self._pose, soak.dies)
            await self._hold_chamber(*tripped, setpoint_c=target_c)
            raise Rewind(f"step {step} soak: {tripped[0].name}")
        now_s = self.clock.now()
        # Soak time excludes the time paused or suspended (a pause longer than max_soak_s
        # must not end the soak as max_soak_reached).
        soaked_s = polls.active_s(now_s, soak.start_s, self._held_total_s(), soak.held0_s)
        soak.record_chamber(now_s, status, target_c)
        probes = (await self._probe_dies(soak.dies, step, target_c, status,
                                         self._t(soak.start_s))
                  if soak.cfg.policy == "predictive" else [])
        try:
            decision = polls.decide_round(
                soak, soaked_s, target_c, self._live,
                lambda serial, taken: self.rate_book.for_decision(serial, self._pose, taken),
                n_positions=self.n_pos, edge=msg.soak.edge,
                order_repeats=msg.soak.order_repeats)
        except BaseException:
            store.add_soak_probes(self.sf, self.id, probes)  # kept, whatever the decision did
            raise
        self._publish(step, "soak", 0, status, target_c,
                      soak_remaining_s=max(0.0, self.eta.soak_s - soaked_s), probes=probes)
        return Poll(decision.stable, polls.soak_poll_wait_s(decision, spec.soak_poll_s))

    def _no_dies(self) -> dict[str, list[rate_gain.Probe]]:
        return {serial: [] for serial in self._live}

    async def _probe_dies(self, dies: dict[str, list[rate_gain.Probe]], step: int,
                          setpoint_c: float, status: ChamberStatus, soak_start_t_s: float
                          ) -> list[dict[str, Any]]:
        """One die-temperature probe of every live sensor: kept in ``dies`` and returned as
        ``soak_probes`` rows (the measured rate gain and a resume need them), which the
        poll stores with its progress in one commit (:meth:`_publish`), as they are taken.

        Every live die at once, as a position's captures (:func:`sensors.read_all`): a
        poll of eight sensors takes one capture's time, not eight.
        """
        n = self.spec.soak_probe_samples

        def read(serial: str) -> Awaitable[Any]:
            return self._sensor_call(serial, "accelerometer.acquire",
                                     functools.partial(self._accelerometer(serial).acquire, n))

        taken = await self._read_live(dies, read)
        rows: list[dict[str, Any]] = []
        for serial, probe in taken.items():
            # mid-capture (captures end together; each keeps its own duration)
            mid_s = self.clock.now() - probe.duration_s / 2.0
            t_s = self._t(mid_s)
            dies[serial].append(rate_gain.Probe(mid_s, t_s, float(probe.sensor_c),
                                       tuple(float(v) for v in probe.mean_g)))
            ref = self._pose_ref or (math.nan, math.nan, math.nan)
            rows.append({
                "sensor": serial, "step": step,
                "soak_start_t_s": soak_start_t_s, "pose": self._pose, "t_s": t_s,
                "setpoint_c": setpoint_c, "chamber_c": status.process_c,
                "sensor_c": probe.sensor_c,
                **_finite({"ref_x": ref[0], "ref_y": ref[1], "ref_z": ref[2]}),
                "ax": probe.mean_g[0], "ay": probe.mean_g[1], "az": probe.mean_g[2],
                "n": probe.n,
            })
        return rows

    # --- the table's pose: the probes' orientation key (rate_gain.py) -------------------
    def _set_pose(self, angles_deg: tuple[float, ...]) -> None:
        """The table stands at ``angles_deg``: the probes' orientation key and reference."""
        from drivers.geometry import reference_for_angles

        self._pose = ",".join(f"{float(a):.1f}" for a in angles_deg)
        self._position_pose = None  # a move of its own (home, park): no position's pose
        try:
            ref = reference_for_angles(angles_deg)
            self._pose_ref = (float(ref[0]), float(ref[1]), float(ref[2]))
        except ValueError:  # a table geometry the reference formula does not cover
            self._pose_ref = None

    async def _fitting(self) -> None:
        """One calibration per live sensor, each stored as it is fitted (a resumed fit skips
        the stored ones); a fit that fails drops that sensor (fails a one-sensor campaign)."""
        camp = store.load_campaign(self.sf, self.id)
        store.set_cursor(self.sf, self.id, self.spec.n_steps - 1, "fitting", self.n_pos,
                         {**self._progress, "phase": "fitting", "fraction": 1.0, "eta_s": 0.0})
        several = len(self.serials) > 1
        done = (set(camp.calibration_ids or {}) if several
                else {self.sensor_serial} if camp.calibration_id is not None else set())
        for serial in self._live:
            if serial in done:
                continue
            cols = store.measurement_columns(self.sf, self.id, serial)
            provenance = {
                "campaign_id": self.id, "rig": camp.rig, "sensor": serial,
                **({"sensors": self.serials} if several else {}),
                "spec": camp.spec, "positions": self.spec.positions,
                "steps_log": camp.steps_log,
                "recording": (f"campaign-{self.id}-{serial}.csv" if several
                              else f"campaign-{self.id}.csv"),
                "sensor_identity": self.identities.get(serial),
                **self.rate_book.provenance(serial),
            }
            try:
                # In a thread: the fit takes ~1 s of CPU and the API shares this event loop.
                values = await asyncio.to_thread(self.calibrate, cols, provenance)
            except Exception as exc:  # one sensor's fit failing drops it, not the service
                self._drop(SensorDropped(serial, f"calibration fit failed: {exc}"))
                continue
            if self.fit_result is None:
                self.fit_result = values.fit
            store.store_calibration(self.sf, self.id, values,
                                    sensor=serial if several else None)

    # --- device helpers -----------------------------------------------------------
    async def _chamber(self) -> ChamberStatus:
        return await self.guard.call("chamber.read_status", self.dev.chamber.read_status)

    async def _move_to(self, angles_deg: tuple[float, ...]) -> None:
        """Command the table and wait for in-position; a table that misses it suspends.

        The table suspender holds (:meth:`_hold`): the table is stopped and the move
        commanded again until it arrives, every ``move_timeout_s``; the campaign fails
        once that lasted ``suspend_limit_s`` of real time. No rewind: the table does not
        disturb the temperature.
        """
        why = await self._move_once(angles_deg)
        if why is not None:
            tt = self.dev.turntable

            async def move_again() -> str | None:
                await self.guard.call("turntable.stop", tt.stop)
                return await self._move_once(angles_deg)

            await self._hold(self.suspenders.table, why, move_again, poll_s=0.0)
        self._set_pose(angles_deg)

    async def _move_once(self, angles_deg: tuple[float, ...]) -> str | None:
        """Command one move and wait up to ``move_timeout_s`` for in-position: None once
        there, else why not."""
        tt = self.dev.turntable
        await self.guard.call("turntable.move_to", lambda: tt.move_to(angles_deg))
        start_s = self.clock.now()
        while True:
            await self.clock.sleep(TURNTABLE_POLL_S)
            st = await self.guard.call("turntable.read_status", tt.read_status)
            if st.in_position and not st.moving:
                return None
            if self.clock.now() - start_s > self.spec.move_timeout_s:
                return table_not_in_position(st, angles_deg, self.clock.now() - start_s)

    async def _hold_chamber(self, susp: Suspender, why: str, *,
                            setpoint_c: float | None) -> None:
        """Hold while a chamber suspender is tripped (band armed with ``setpoint_c``)."""

        async def still_tripped() -> str | None:
            status = await self._chamber()
            if setpoint_c is not None and abs(status.setpoint_c - setpoint_c) > 1e-3:
                # Someone changed the controller behind the engine (a front panel, a
                # process that lost the rig parking it): command our setpoint again.
                await self.guard.call("chamber.set_setpoint",
                                      functools.partial(self.dev.chamber.set_setpoint, setpoint_c))
            tripped = self.suspenders.check_chamber(status, setpoint_c)
            return None if tripped is None else tripped[1]

        await self._hold(susp, why, still_tripped,
                         poll_s=min(self.spec.soak_poll_s, HOLD_POLL_S))

    async def _hold(self, susp: Suspender, why: str,
                    still_tripped: Callable[[], Awaitable[str | None]], *,
                    poll_s: float) -> None:
        """Suspended (no readings, chamber at its setpoint) until ``still_tripped()`` has
        said None for ``susp.clear_s``: the one hold loop (:func:`guard.hold`), with the
        campaign's checkpoint (pause, abort) every round; paused time is not held time."""
        await hold(self.clock, susp, why, still_tripped, poll_s=poll_s,
                   checkpoint=self._checkpoint, wait=self._wait,
                   on_hold=lambda why: self._suspend(f"{susp.name}: {why}"),
                   on_clear=lambda since_s: self._resumed(susp, since_s),
                   paused_s=lambda: self._paused_s)

    def _resumed(self, susp: Suspender, since_s: float) -> None:
        self.suspension_log.append({"suspender": susp.name, "t_s": round(self._t(since_s), 3),
                                    "held_s": round(self.clock.now() - since_s, 3)})
        self._unsuspend()

    async def _park_through_cancel(self) -> asyncio.CancelledError | None:
        """Run :meth:`_drive_safe` to its end even if we are cancelled meanwhile.

        A cancel can arrive while the rig is being parked: the manager cancels
        the run when it finds the lease lost, which races the runner's own
        ``LeaseLost`` exit, and a shutdown can cancel twice. Cancelling the park
        itself would leave the table where it stood (seen: 90° off home). So the
        park runs as its own task behind :func:`asyncio.shield`; a cancel that
        arrives meanwhile is absorbed and returned, to be raised once the rig is
        safe. Every device's park is bounded (a timeout per try, a few tries:
        park.py), so this cannot wait for ever.
        """
        park = asyncio.ensure_future(self._drive_safe())
        late: asyncio.CancelledError | None = None
        while True:
            try:
                await asyncio.shield(park)
                return late
            except asyncio.CancelledError as exc:
                if park.done():  # the park itself was cancelled (loop shutting down)
                    raise
                late = late or exc
                task = asyncio.current_task()
                if task is not None:
                    task.uncancel()

    async def _drive_safe(self) -> None:
        """The rig's safe state: each device parks itself (service/engine/park.py).

        The one place every exit of :meth:`run` ends. Not through the guard (a
        pending abort or a suspension must not stop it): each device's park has
        its own timeout and a few tries, and one device's failure never skips
        another's. A campaign's ``safe_c`` overrides the chamber's own safe
        setpoint. The outcome per device is kept in ``self.safe_report``; what
        did not park is logged. On a fenced runner a lost lease parks nothing
        (``not sent: lease lost``): every park is a fenced command.
        """
        spec = getattr(self, "spec", None)  # None: the spec was not parsed
        self.safe_report = await park_rig(self.dev, self.clock,
                                          safe_c=getattr(spec, "safe_c", None))
        for device, outcome in self.safe_report.items():
            if not parked(outcome):
                log.error("campaign %s: %s not parked: %s", self.id, device, outcome)

    # --- control: pause / resume / abort --------------------------------------------
    async def _checkpoint(self) -> None:
        """A safe point: apply a pending pause or abort (resume clears a stale request)."""
        ctl = store.read_control(self.sf, self.id)
        if ctl.state == "aborted" or ctl.requested_action == "abort":
            raise AbortRequested("operator")
        if ctl.requested_action == "resume" and ctl.state == "running":
            store.clear_action(self.sf, self.id, "resume")
        if ctl.requested_action == "pause" or ctl.state == "paused":
            await self._paused()

    async def _paused(self) -> None:
        """Hold: chamber keeps its setpoint, table at rest; wait for resume or abort."""
        if not store.transition(self.sf, self.id, "paused", clear_action=True,
                                progress={**self._progress, "paused": True}):
            await self._lost_control()
            return
        await self.guard.call("turntable.stop", self.dev.turntable.stop)
        paused_since_s = self.clock.now()
        try:
            await self._wait_for_resume()
        finally:
            paused_s = self.clock.now() - paused_since_s
            self._paused_s += paused_s
            if self._held_since_s is None:  # inside a suspension its interval covers it
                self._held_s += paused_s

    async def _wait_for_resume(self) -> None:
        while True:
            await self.clock.sleep(self.spec.soak_poll_s)
            ctl = store.read_control(self.sf, self.id)
            if ctl.state == "aborted" or ctl.requested_action == "abort":
                raise AbortRequested("operator")
            if ctl.requested_action == "resume" or ctl.state in ("running", "queued"):
                if not store.transition(self.sf, self.id, "running", clear_action=True,
                                        progress={**self._progress, "paused": False}):
                    await self._lost_control()
                return

    async def _lost_control(self) -> None:
        """A state write lost its race: obey what the database now says."""
        ctl = store.read_control(self.sf, self.id)
        if ctl.state == "aborted" or ctl.requested_action == "abort":
            raise AbortRequested("operator")
        if ctl.state in TERMINAL:
            raise CampaignFailed(f"campaign became {ctl.state} under the engine")

    async def _wait(self, dt_s: float) -> None:
        """Sleep ``dt_s`` on the clock, checking for an abort every poll (≤ 60 s).

        A long settle or soak wait is interruptible: a pending abort waits at most
        one poll period, not the whole wait.
        """
        end_s = self.clock.now() + dt_s
        while (left_s := end_s - self.clock.now()) > 0:
            chunk_s = min(left_s, self.spec.soak_poll_s, ABORT_CHECK_S)
            await self.clock.sleep(chunk_s)
            # More to wait: look for an abort now (the next device call checks after the last).
            if chunk_s < left_s and self._abort_asked():
                raise AbortRequested("operator")

    def _abort_asked_recently(self) -> bool:
        """The guard's check before every device call, read at most every 50 ms of loop time.

        On a real rig a device call takes longer than that, so this is every call;
        on a VirtualClock (tests, demo) thousands of calls pass per wall second and
        the database read (~1 ms) would dominate the run. Waits and checkpoints
        read unthrottled (:meth:`_abort_asked`).
        """
        now_s = asyncio.get_running_loop().time()  # the event loop's monotonic time: no waiting
        if now_s - self._abort_checked_s < ABORT_READ_EVERY_S:
            return False
        self._abort_checked_s = now_s
        return self._abort_asked()

    def _abort_asked(self) -> bool:
        ctl = store.read_control(self.sf, self.id)
        return ctl.state == "aborted" or ctl.requested_action == "abort"

    def _suspend(self, reason: str) -> None:
        if self._held_since_s is None:
            self._held_since_s = self.clock.now()
        self._progress = {**self._progress, "suspended_reason": reason}
        store.update_campaign(self.sf, self.id, suspended_reason=reason, progress=self._progress)

    def _unsuspend(self) -> None:
        if self._held_since_s is not None:
            self._held_s += self.clock.now() - self._held_since_s
            self._held_since_s = None
        self._progress = {k: v for k, v in self._progress.items() if k != "suspended_reason"}
        store.update_campaign(self.sf, self.id, suspended_reason=None, progress=self._progress)

    # --- progress -----------------------------------------------------------------------
    def _t(self, clock_s: float) -> float:
        """Campaign time t_s (continuous across restarts) from a clock reading."""
        return self._t_base_s + (clock_s - self._clock0_s)

    def _publish(self, step: int, phase: str, position: int, status: ChamberStatus,
                 target_c: float, *, soak_remaining_s: float | None = None,
                 write: bool = True, probes: Sequence[dict[str, Any]] = ()
                 ) -> dict[str, Any]:
        """The progress of this point of the run, written to the campaign (``write``) with
        the poll's die ``probes`` in the same commit (:func:`store.add_soak_probes`)."""
        n_done = self.eta.n_done
        progress = {
            "step": step, "steps": self.spec.n_steps, "phase": phase, "position": position,
            "positions": self.n_pos,
            "fraction": round(n_done / (self.spec.n_steps * self.n_pos), 4),
            "chamber_c": round(status.process_c, 3), "setpoint_c": target_c,
            # None: a ramp's time is not known yet (a step at an unstated rate).
            "eta_s": None if (eta_s := self.eta.eta_s(step, phase, soak_remaining_s)) is None
            else round(eta_s, 1),
            # The same remaining time on the wall: a sped-up rig's clock runs faster.
            "eta_wall_s": None if eta_s is None else round(eta_s / clock_speed(self.clock), 1),
            "t_s": round(self._t(self.clock.now()), 3),
        }
        if self._ramp is not None:  # a ramp has sweeps, not steps: its prediction's ETA
            progress.update(self._ramp.fields(status, target_c))
            progress["eta_wall_s"] = round(progress["eta_s"] / clock_speed(self.clock), 1)
        self._progress = progress
        if probes:
            store.add_soak_probes(self.sf, self.id, list(probes),
                                  progress=progress if write else None)
        elif write:
            store.update_campaign(self.sf, self.id, progress=progress)
        return progress


def _ref_text(ref_g: tuple[float, ...]) -> str:
    return "(" + ", ".join(f"{float(v):+.3f}" for v in ref_g) + ") g"


class Rewind(Exception):  # noqa: N818 - a control-flow signal, not an error
    """A suspender held the campaign: resume the plan from its stored measurements."""


def _finite(d: dict[str, float]) -> dict[str, float | None]:
    return {k: (v if math.isfinite(v) else None) for k, v in d.items()}


def commanded_reference(ref_g: Any, pose: dict[str, float | None]) -> tuple[float, ...]:
    """The reference a row stores: the direction its commanded pose puts gravity along,
    |ref| kept, where the pose is known and differs from the schedule's direction.

    Why: a hand axis stops only at its indexer's steps, and a step within
    ``drivers.geometry.HAND_STEP_TOL_DEG`` (0.5°) of the angle a reference needs is taken
    for it; the sensor then stands at the step, not at the schedule's direction, and a
    reference-mode fit takes ``ref_*`` as the truth (0.5° is 8.7 mg across it). Elsewhere
    the two agree to rounding and the schedule's reference is kept exactly."""
    ref = np.asarray(ref_g, float)
    q = [pose.get(c) for c in POSE_COLUMNS]
    if any(v is None for v in q):
        return tuple(float(v) for v in ref)
    g = pose_rows(np.array([q], float), (2,))[0, :, 0]
    mag = float(np.linalg.norm(ref))
    if float(np.linalg.norm(g * mag - ref)) <= 1e-9 * max(mag, 1.0):
        return tuple(float(v) for v in ref)
    return tuple(float(v) for v in g * mag)

