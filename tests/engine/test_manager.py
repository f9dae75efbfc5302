"""Rig leases: the database decides which process runs a rig; expired leases are taken over."""

from __future__ import annotations

import time

from engine_helpers import SMALL_SPEC, add_campaign

from service.engine import store
from service.engine.manager import CampaignManager


def test_one_lease_per_rig_and_takeover_after_expiry(sf) -> None:
    cid = add_campaign(sf)
    a = CampaignManager(sf, owner="proc-a", lease_s=0.3)
    b = CampaignManager(sf, owner="proc-b", lease_s=0.3)
    assert a._claim("sim", cid)
    assert not b._claim("sim", cid)  # live lease held by a
    assert a._claim("sim", cid)  # re-claiming our own lease is fine
    assert a._renew("sim")
    time.sleep(0.45)  # a "dies": no renewal
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
    store.update_campaign(sf, orphan, state="paused")
    assert m._pick("sim") is None  # a paused campaign keeps the rig until resumed or aborted
    other = CampaignManager(sf, owner="proc-b", lease_s=30)
    store.update_campaign(sf, orphan, state="completed")
    assert other._claim("sim", q1)
    assert m._pick("sim") is None  # someone else's live lease
