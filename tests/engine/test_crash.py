"""SIGKILL a service process mid-campaign; another process finishes it: nothing lost or doubled.

Real stacks: the manager, the rig lease, the simulated rig over loopback
Modbus/serial, the calibration core; a VirtualClock so it runs in seconds.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from engine_helpers import add_campaign
from sqlalchemy import select

from service.db.models import Campaign, Measurement, RigLease

WORKER = Path(__file__).with_name("crash_worker.py")
ROOT = Path(__file__).resolve().parents[2]
SPEC = {"setpoints_c": [0.0, 20.0, 40.0], "soak_min": 20, "positions": "table1",
        "samples_per_position": 50, "ramp_c_per_min": 2.0}
N_STEPS, N_POS = 3, 24


def start_worker(url: str, cid: int) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, str(WORKER), url, str(cid), "1.5"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def count(sf, cid: int) -> int:  # type: ignore[no-untyped-def]
    with sf() as s:
        return len(s.execute(select(Measurement.id).where(Measurement.campaign_id == cid)).all())


def test_sigkill_mid_campaign_then_another_process_completes(sf, migrated_db_url) -> None:
    cid = add_campaign(sf, SPEC)
    kills = 0
    for target in (10, 40):  # kill once in step 0, once in step 1
        p = start_worker(migrated_db_url, cid)
        deadline = time.monotonic() + 60
        while count(sf, cid) < target and p.poll() is None and time.monotonic() < deadline:
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
