"""Failover that cannot hang: a claim waits a bounded time for the lease row, off the loop.

A holder stalled inside a fenced commit (store._check_fence: a no-op UPDATE of
its rig_leases row, transaction left open) blocks every other process's claim,
the INSERT as much as the UPDATE. The claim gives up after the lease lock
timeout and the scan tries again; meanwhile the event loop (the HTTP API's)
keeps running. On PostgreSQL the stalled holder's session is ended by the
server, so the takeover follows without it ever resuming.
"""

from __future__ import annotations

import asyncio
import datetime as dt
import time
from typing import Any

import pytest
from engine_helpers import add_campaign
from sqlalchemy import text, update

from service.db.models import RigLease
from service.engine import store
from service.engine.manager import CampaignManager

LOCK_S = 0.3  # the lease lock timeout, shortened for the test
IDLE_S = 0.6  # the stalled fenced transaction's idle timeout (PostgreSQL), shortened


@pytest.fixture
def short_timeouts(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(store, "LEASE_LOCK_TIMEOUT_S", LOCK_S)
    monkeypatch.setattr(store, "FENCED_IDLE_TIMEOUT_S", IDLE_S)


def expired_lease_of_a(sf: Any) -> int:
    """A running campaign whose holder (proc-a) stopped renewing: an orphan to take over."""
    cid = add_campaign(sf, state="running")
    assert CampaignManager(sf, owner="proc-a", lease_s=30)._claim("sim", cid)
    with sf() as s:
        s.execute(update(RigLease).where(RigLease.rig == "sim").values(
            lease_until=store.now_utc() - dt.timedelta(seconds=1)))
        s.commit()
    return cid


async def scan_while_counting_ticks(mgr: CampaignManager) -> tuple[float, int]:
    """(wall seconds of one scan, ticks a 10 ms ticker got meanwhile on the same loop)."""
    ticks = 0

    async def ticker() -> None:
        nonlocal ticks
        while True:
            await asyncio.sleep(0.01)
            ticks += 1

    tick_task = asyncio.create_task(ticker())
    t0 = time.monotonic()
    await asyncio.wait_for(mgr.run_once(), 10 * LOCK_S)
    took_s = time.monotonic() - t0
    tick_task.cancel()
    return took_s, ticks


async def test_a_claim_behind_a_stalled_fenced_commit_gives_up_and_the_loop_runs(  # type: ignore[no-untyped-def]
        sf, short_timeouts) -> None:
    cid = expired_lease_of_a(sf)
    stalled = sf()
    if stalled.get_bind().dialect.name == "sqlite":
        # SQLite locks the database, not the row: a writer stalled mid-commit holds it all.
        stalled.connection().exec_driver_sql("BEGIN IMMEDIATE")
    else:
        stalled.execute(text("SET LOCAL idle_in_transaction_session_timeout = 0"))
        stalled.execute(update(RigLease).where(RigLease.rig == "sim")
                        .values(owner=RigLease.owner))  # what _check_fence does, left open
    b = CampaignManager(sf, owner="proc-b", lease_s=30)
    try:
        took_s, ticks = await scan_while_counting_ticks(b)
        assert LOCK_S * 0.8 <= took_s < LOCK_S + 1.0  # waited for the lock, then gave up
        assert ticks >= took_s / 0.01 * 0.5  # the loop kept running meanwhile
        assert "sim" not in b._runs
    finally:
        stalled.rollback()
        stalled.close()
    assert b._claim("sim", cid)  # the lock gone, the next scan takes the rig over


async def test_postgres_ends_the_stalled_holders_session_and_the_takeover_follows(  # type: ignore[no-untyped-def]
        sf, short_timeouts) -> None:
    """The holder never resumes: the server ends its idle transaction, the claim succeeds."""
    if sf.kw["bind"].dialect.name != "postgresql":
        pytest.skip("SQLite has no server to end a stalled writer's transaction")
    cid = expired_lease_of_a(sf)
    with store.lease_session(sf) as holder_s:
        with sf() as s:  # make the expired lease live again for proc-a's fenced commit
            s.execute(update(RigLease).where(RigLease.rig == "sim").values(
                lease_until=store.now_utc() + dt.timedelta(seconds=0.5)))
            s.commit()
        store._check_fence(holder_s, store.Fence("sim", "proc-a"), cid)  # then SIGSTOP
        time.sleep(0.6)  # the lease expires while the holder sleeps inside its commit
        b = CampaignManager(sf, owner="proc-b", lease_s=30)
        deadline = time.monotonic() + 5.0
        while not b._claim("sim", cid):
            assert time.monotonic() < deadline, "no takeover while the holder stalls"
        took_s = 5.0 - (deadline - time.monotonic())
        assert took_s < IDLE_S + LOCK_S + 0.5
        with pytest.raises(Exception, match="idle-in-transaction|terminat|closed"):
            holder_s.commit()  # the stalled holder's transaction is gone
