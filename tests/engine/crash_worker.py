"""A service-like process for the crash test: a CampaignManager on the simulated rig.

Usage: python crash_worker.py DB_URL CAMPAIGN_ID LEASE_S
Runs until the campaign reaches a terminal state (or is SIGKILLed by the test).
Prints ``commit STEP POSITION`` (flushed) after each measurement this process
committed, so a test can tell which process wrote what.
"""

from __future__ import annotations

import asyncio
import sys

from drivers.clock import VirtualClock
from service.db.models import Campaign
from service.db.session import make_session_factory
from service.engine import store
from service.engine.manager import CampaignManager
from service.engine.states import TERMINAL
from service.engine.store import fast_sqlite_commits


def _report_commits() -> None:
    commit = store.commit_measurements

    def reporting(sf, campaign_id, rows, *args, **kwargs):  # type: ignore[no-untyped-def]
        stored = commit(sf, campaign_id, rows, *args, **kwargs)
        if stored:
            print("commit", rows[0]["step"], rows[0]["position"], flush=True)
        return stored

    store.commit_measurements = reporting  # type: ignore[assignment]


async def main(url: str, campaign_id: int, lease_s: float) -> int:
    _report_commits()
    sf = make_session_factory(url)
    fast_sqlite_commits(sf)
    mgr = CampaignManager(sf, clock_factory=lambda: VirtualClock(idle_wall_s=0.0005),
                          lease_s=lease_s, poll_wall_s=0.2)
    await mgr.start()
    try:
        while True:
            await asyncio.sleep(0.2)
            with sf() as s:
                c = s.get(Campaign, campaign_id)
                if c is not None and c.state in TERMINAL:
                    print("final", c.state, c.error, flush=True)
                    return 0
    finally:
        await mgr.stop()


if __name__ == "__main__":
    sys.exit(asyncio.run(main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]))))
