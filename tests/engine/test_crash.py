"""SIGKILL a service process mid-campaign; another process finishes it: nothing lost or doubled.

Real stacks: the manager, the rig lease, the simulated rig over loopback
Modbus/serial, the calibration core; a VirtualClock so it runs in seconds.
"""


from __future__ import annotations

import signal
import time
from collections import Counter

from crash_helpers import N_POS, N_STEPS, SPEC, start_worker
from engine_helpers import add_campaign, n_measurements
from sqlalchemy import select

from service.db.models import Campaign, Measurement, RigLease


def test_sigkill_mid_campaign_then_another_process_completes(sf, migrated_db_url) -> None:
    cid = add_campaign(sf, SPEC)
    kills = 0
    for target in (10, 40):  # kill once in step 0, once in step 1
        p = start_worker(migrated_db_url, cid)
        deadline = time.monotonic() + 60
        while n_measurements(sf, cid) < target and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert p.poll() is None, p.stdout.read() if p.stdout else ""
        p.send_signal(signal.SIGKILL)
        p.wait()
        kills += 1
        with sf() as s:
            c = s.get(Campaign, cid)
            assert c.state == "running"  # as the dead process left it
            assert s.get(RigLease, "sim") is not None  # its lease stays until it expires
    p = start_worker(migrated_db_url, cid)
    out, _ = p.communicate(timeout=120)
    assert p.returncode == 0, out
    with sf() as s:
        c = s.get(Campaign, cid)
        rows = s.execute(select(Measurement.step, Measurement.position, Measurement.t_s)
                         .where(Measurement.campaign_id == cid).order_by(Measurement.id)).all()
        assert c.state == "completed", (c.error, out)
        assert c.calibration_id is not None
        assert s.get(RigLease, "sim") is None  # released at the end
    counts = Counter((r[0], r[1]) for r in rows)
    assert set(counts) == {(a, b) for a in range(N_STEPS) for b in range(N_POS)}
    assert max(counts.values()) == 1
    t = [r[2] for r in rows]
    assert t == sorted(t)  # t_s continues across restarts
    assert kills == 2
