"""CampaignManager: picks campaigns per rig, holds the rig lease, runs them.

One loop per service process. For every rig it looks for work:

1. a ``running`` campaign whose lease expired (its process died): crash recovery;
2. else, when the rig holds no campaign paused *after it started* (that one keeps
   the rig until resumed or aborted, like the API's ``rig_busy``), the oldest
   ``queued`` one, a resumed campaign that had started first. A campaign paused
   while still queued never touched the rig and holds nothing.

It claims the rig lease in the database (INSERT, or a conditional UPDATE
where the lease expired or is already ours), so two service processes on one
PostgreSQL never run two campaigns on one rig. The lease is renewed in *wall*
time (it protects against dead processes, which die in real time) by a
background task; if a renewal finds the lease taken, the run is cancelled.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import importlib
import logging
import os
import socket
import uuid
from collections.abc import Callable, Collection
from typing import Any

from sqlalchemy import delete, insert, select, update
from sqlalchemy.exc import IntegrityError, OperationalError
from sqlalchemy.orm import Session, sessionmaker

from drivers.clock import Clock, RealClock, ScaledClock
from service.db.models import Campaign, Rig, RigLease
from service.db.timestamps import as_utc, utcnow
from service.engine import store
from service.engine.placement import hand_placed_calibrate, hand_placed_references
from service.engine.rigs import open_rig, rig_time_scale
from service.engine.runner import CampaignRunner
from service.engine.store import cas_transition

log = logging.getLogger(__name__)
POLL_WALL_S = 1.0


# Imported by the engine on first use, heavy: the plan's travel order
# (calibration/position_order.py) imports the discrepancy package and scipy, ~2 s on a
# loaded host; on the event loop that is 2 s without HTTP answers at the first campaign's
# start, or at a takeover.
LAZY_ENGINE_MODULES = ("calibration.position_order",)


async def _import_engine_modules() -> None:
    """Import :data:`LAZY_ENGINE_MODULES` in a thread (a no-op once imported)."""
    for name in LAZY_ENGINE_MODULES:
        with contextlib.suppress(Exception):
            await asyncio.to_thread(importlib.import_module, name)


def default_owner() -> str:
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


class CampaignManager:
    """Runs queued campaigns (and recovers orphaned ones) on every rig in the database."""

    def __init__(
        self,
        session_factory: sessionmaker[Session],
        *,
        sim_speed: float = 600.0,
        clock_factory: Callable[[], Clock] | None = None,
        owner: str | None = None,
        lease_s: float = 30.0,
        poll_wall_s: float = POLL_WALL_S,
        rig_options: dict[str, Any] | None = None,
        rigs: Collection[str] | None = None,
    ) -> None:
        self.sf = session_factory
        self.sim_speed = sim_speed
        # An injected clock (tests, demo) serves every rig; otherwise a sim rig runs
        # at sim_speed and a modbus rig at its own time_scale (1 = wall clock).
        self._clock_injected = clock_factory is not None
        self.clock_factory = clock_factory or (lambda: ScaledClock(sim_speed))
        self.owner = owner or default_owner()
        self.lease_s = lease_s
        self.poll_wall_s = poll_wall_s
        self.rig_options = rig_options or {}
        # The rigs this process drives (``--rigs``); None: every rig in the database.
        self.rigs = None if rigs is None else frozenset(rigs)
        self._loop_task: asyncio.Task | None = None
        self._runs: dict[str, asyncio.Task] = {}  # rig name -> running campaign task

    async def start(self) -> None:
        if self._loop_task is None:
            self._loop_task = asyncio.create_task(self._loop(), name="campaign-manager")

    async def stop(self) -> None:
        """Cancel the loop and every run; leases are released so another process takes over."""
        tasks = [t for t in (self._loop_task, *self._runs.values()) if t is not None]
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await t
        self._loop_task = None
        self._runs.clear()

    async def run_once(self) -> None:
        """One scan of all rigs (the loop body; tests call it directly).

        Its database work runs in a thread (``asyncio.to_thread``): a claim waiting for
        a lock (at most ``store.LEASE_LOCK_TIMEOUT_S``) must not stop the event loop the
        HTTP API and the other rigs' campaigns share.
        """
        rigs = await asyncio.to_thread(self._rig_names)
        for rig in rigs:
            if self.rigs is not None and rig not in self.rigs:
                continue  # another host drives it
            task = self._runs.get(rig)
            if task is not None and not task.done():
                continue
            campaign_id = await asyncio.to_thread(self._pick, rig)
            if campaign_id is None or not await asyncio.to_thread(self._claim, rig,
                                                                  campaign_id):
                continue
            self._runs[rig] = asyncio.create_task(self._run(rig, campaign_id),
                                                  name=f"campaign-{campaign_id}")

    def _rig_names(self) -> list[str]:
        with self.sf() as s:
            return list(s.execute(select(Rig.name)).scalars().all())

    # --- loop ---------------------------------------------------------------------
    async def _loop(self) -> None:
        asyncio.create_task(_import_engine_modules())  # warm up meanwhile (scans go on)
        while True:
            try:
                await self.run_once()
            except Exception:  # a DB hiccup must not kill the service's runner loop
                log.exception("campaign manager scan failed")
            await asyncio.sleep(self.poll_wall_s)

    def _pick(self, rig: str) -> int | None:
        with self.sf() as s:
            lease = s.get(RigLease, rig)
            now = utcnow()
            lease_live = (lease is not None and lease.owner != self.owner
                          and (as_utc(lease.lease_until) or now) > now)
            if lease_live:
                return None
            orphan = s.execute(
                select(Campaign.id).where(Campaign.rig == rig, Campaign.state == "running")
                .order_by(Campaign.id).limit(1)
            ).scalar()
            if orphan is not None:
                return int(orphan)
            paused = s.execute(
                select(Campaign.id).where(Campaign.rig == rig, Campaign.state == "paused",
                                          Campaign.started_at.is_not(None)).limit(1)
            ).scalar()
            if paused is not None:
                return None
            queued = s.execute(
                select(Campaign.id).where(Campaign.rig == rig, Campaign.state == "queued")
                .order_by(Campaign.started_at.is_(None), Campaign.created_at, Campaign.id)
                .limit(1)
            ).scalar()
            return None if queued is None else int(queued)

    def _claim(self, rig: str, campaign_id: int) -> bool:
        """Take the rig lease for ``campaign_id``; the database arbitrates between processes.

        Both statements give up after ``store.LEASE_LOCK_TIMEOUT_S``: a stalled holder may
        sit inside a fenced commit holding the lease row's lock (store._check_fence), and
        the INSERT waits for that lock as the UPDATE does. The next scan tries again.
        """
        now = utcnow()
        until = now + dt.timedelta(seconds=self.lease_s)
        with store.lease_session(self.sf) as s:
            try:
                store.bound_lease_locks(s)
                s.execute(insert(RigLease).values(rig=rig, campaign_id=campaign_id,
                                                  owner=self.owner, lease_until=until))
                s.commit()
                return True
            except IntegrityError:
                s.rollback()
            except OperationalError:  # the lock wait timed out
                s.rollback()
                return False
            try:
                store.bound_lease_locks(s)
                res = s.execute(
                    update(RigLease)
                    .where(RigLease.rig == rig,
                           (RigLease.lease_until < now) | (RigLease.owner == self.owner))
                    .values(campaign_id=campaign_id, owner=self.owner, lease_until=until)
                )
                s.commit()
            except OperationalError:
                s.rollback()
                return False
            return res.rowcount == 1

    def _renew(self, rig: str) -> bool:
        until = utcnow() + dt.timedelta(seconds=self.lease_s)
        with store.lease_session(self.sf) as s:
            store.bound_lease_locks(s)
            res = s.execute(
                update(RigLease).where(RigLease.rig == rig, RigLease.owner == self.owner)
                .values(lease_until=until)
            )
            s.commit()
            return res.rowcount == 1

    def _release(self, rig: str) -> None:
        with store.lease_session(self.sf) as s:
            store.bound_lease_locks(s)
            s.execute(delete(RigLease).where(RigLease.rig == rig, RigLease.owner == self.owner))
            s.commit()

    async def _run(self, rig: str, campaign_id: int) -> None:
        renewer = asyncio.create_task(self._keep_lease(rig, asyncio.current_task()))
        try:
            await _import_engine_modules()
            with self.sf() as s:
                row = s.execute(select(Rig).where(Rig.name == rig)).scalar_one()
                rig_cfg = {"name": row.name, "chamber": row.chamber, "turntable": row.turntable,
                           "sensors": row.sensors}
                # The sim twin mounts the sensors the campaign names (issue 12).
                serials = list((s.get(Campaign, campaign_id).spec or {}).get("sensors") or [])
            clock = self._clock_for(rig_cfg)
            async with open_rig(rig_cfg, clock, seed=campaign_id, serials=serials,
                                **self.rig_options) as devices:
                fence = store.Fence(rig, self.owner)
                options: dict[str, Any] = {}
                if hand_placed_references(rig_cfg.get("turntable")):
                    # hand-placed references (a fixture, or a hand-set second axis): fitted
                    # as approximate (docs/manual-fixtures.md, "The fit: ref_tol_deg")
                    options["calibrate"] = hand_placed_calibrate()
                await CampaignRunner(self.sf, campaign_id, devices, clock, fence=fence,
                                     **options).run()
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # the rig could not be opened: fail the campaign, not the service
            # (the engine itself handles everything raised while it runs, safe state included)
            log.exception("campaign %s could not run", campaign_id)
            with contextlib.suppress(Exception):
                for from_state in ("queued", "running"):
                    with self.sf() as s:
                        ok = cas_transition(s, campaign_id, from_state, "failed",
                                            error=f"engine error: {type(exc).__name__}: {exc}",
                                            requested_action=None)
                        s.commit()
                    if ok:
                        break
        finally:
            renewer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await renewer
            with contextlib.suppress(Exception):
                await asyncio.to_thread(self._release, rig)

    def _clock_for(self, rig_cfg: dict[str, Any]) -> Clock:
        scale = None if self._clock_injected else rig_time_scale(rig_cfg)
        if scale is None:
            return self.clock_factory()
        return RealClock() if scale == 1.0 else ScaledClock(scale)

    async def _keep_lease(self, rig: str, run_task: asyncio.Task | None) -> None:
        while True:
            await asyncio.sleep(self.lease_s / 3.0)
            try:
                ok = await asyncio.to_thread(self._renew, rig)
            except Exception:
                log.exception("lease renewal failed for rig %s", rig)
                continue
            if not ok and run_task is not None:  # someone else holds the rig now: stop touching it
                log.error("lost the lease on rig %s; stopping its campaign", rig)
                run_task.cancel()
                return
