"""Rig leases: the database decides which process runs a rig; expired leases are taken over."""

from __future__ import annotations

import datetime as dt

from engine_helpers import SMALL_SPEC, add_campaign

from service.engine import store
from service.engine.manager import CampaignManager


def test_one_lease_per_rig_and_takeover_after_expiry(sf, monkeypatch) -> None:
    # The lease's clock is set here, not slept on: with a 0.3-s lease and real sleeps the
    # "live lease" check failed on a loaded machine, where the two claims were > 0.3 s apart.
    from service.engine import manager

    t0 = manager.utcnow()
    now = [t0]
    monkeypatch.setattr(manager, "utcnow", lambda: now[0])
    cid = add_campaign(sf)
    a = CampaignManager(sf, owner="proc-a", lease_s=30.0)
    b = CampaignManager(sf, owner="proc-b", lease_s=30.0)
    assert a._claim("sim", cid)
    now[0] = t0 + dt.timedelta(seconds=29.0)
    assert not b._claim("sim", cid)  # live lease held by a
    assert a._claim("sim", cid)  # re-claiming our own lease is fine (until t0 + 59 s)
    assert a._renew("sim")
    now[0] = t0 + dt.timedelta(seconds=58.0)
    assert not b._claim("sim", cid)  # the renewal moved the lease on
    now[0] = t0 + dt.timedelta(seconds=60.0)  # a "dies": no renewal
    assert b._claim("sim", cid)
    assert not a._renew("sim")  # a learns it lost the rig
    b._release("sim")
    assert a._claim("sim", cid)


def test_pick_prefers_orphaned_running_then_oldest_queued(sf) -> None:
    m = CampaignManager(sf, owner="proc-a")
    q1 = add_campaign(sf, SMALL_SPEC)
    add_campaign(sf, SMALL_SPEC)
    assert m._pick("sim") == q1
    orphan = add_campaign(sf, SMALL_SPEC, state="running")
    assert m._pick("sim") == orphan
    store.update_campaign(sf, orphan, state="paused", started_at=store.now_utc())
    assert m._pick("sim") is None  # a started, paused campaign keeps the rig until resumed
    other = CampaignManager(sf, owner="proc-b", lease_s=30)
    store.update_campaign(sf, orphan, state="completed")
    assert other._claim("sim", q1)
    assert m._pick("sim") is None  # someone else's live lease


def test_a_campaign_paused_while_queued_does_not_hold_the_rig(sf) -> None:
    """Pausing a queued campaign must not jam the queue behind it (it never touched the rig)."""
    from service.campaigns import apply_action, rig_busy

    m = CampaignManager(sf, owner="proc-a")
    first = add_campaign(sf, SMALL_SPEC)
    second = add_campaign(sf, SMALL_SPEC)
    with sf() as s:
        assert apply_action(s, first, "pause").state == "paused"
    assert m._pick("sim") == second
    with sf() as s:
        assert not rig_busy(s, "sim")
        assert apply_action(s, first, "resume").state == "queued"  # through the table
    assert m._pick("sim") == first


def test_transition_is_conditional_on_the_from_state(sf) -> None:
    """Two writers racing from the same read: exactly one wins."""
    from service.engine.store import cas_transition

    cid = add_campaign(sf, SMALL_SPEC, state="running")
    with sf() as a, sf() as b:
        won_a = cas_transition(a, cid, "running", "aborted")
        a.commit()
        won_b = cas_transition(b, cid, "running", "completed")
        b.commit()
    assert (won_a, won_b) == (True, False)
    assert store.load_campaign(sf, cid).state == "aborted"
    with sf() as s:  # and only moves the table allows
        assert not cas_transition(s, cid, "aborted", "running")


async def test_a_measurement_commit_is_fenced_by_the_rig_lease(sf) -> None:  # type: ignore[no-untyped-def]
    """A process that lost the lease (stalled past it) writes nothing more, even before
    its renewal notices: the commit itself checks the lease in its transaction."""
    import asyncio

    from engine_fakes import make_fake_rig
    from engine_helpers import fake_calibrate
    from sqlalchemy import select, update

    from drivers.clock import VirtualClock
    from service.db.models import Measurement, RigLease
    from service.engine.runner import CampaignRunner

    def n_rows() -> int:
        with sf() as s:
            return len(s.execute(select(Measurement.id)
                                 .where(Measurement.campaign_id == cid)).all())

    clock = VirtualClock(idle_wall_s=0.0)
    rig = make_fake_rig(clock)
    cid = add_campaign(sf)
    a = CampaignManager(sf, owner="proc-a", lease_s=3600)  # its renewal would come far too late
    assert a._claim("sim", cid)
    runner = CampaignRunner(sf, cid, rig.devices, clock, calibrate=fake_calibrate,
                            fence=store.Fence("sim", "proc-a"))
    task = asyncio.create_task(runner.run())
    while n_rows() < 3:
        await asyncio.sleep(0.001)
    with sf() as s:  # proc-b took the rig over while proc-a was stalled
        s.execute(update(RigLease).where(RigLease.rig == "sim").values(owner="proc-b"))
        s.commit()
    n_at_takeover = n_rows()
    assert await asyncio.wait_for(task, 30) == "running"  # left for proc-b, not failed
    assert n_rows() == n_at_takeover
    # not parked: the rig is proc-b's now (tests/engine/test_fencing.py)
    assert rig.physics.setpoint_c == -10.0
