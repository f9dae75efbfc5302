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


def test_stalled_lease_holder_writes_nothing_after_it_resumes(sf, migrated_db_url) -> None:
    """Three processes, one database: A is SIGSTOPped past its lease, B takes the rig over,
    A is SIGCONTed (its renewal or its next, fenced, commit stops it: nothing written while
    B holds the rig), then B is SIGKILLed and C completes. No measurement is lost, none is
    written twice, A writes nothing after SIGCONT."""
    cid = add_campaign(sf, SPEC)
    a = start_worker(migrated_db_url, cid)
    assert a.stdout is not None
    lines_a = 0
    while lines_a < 10:  # stop A just after a commit: outside any write transaction
        line = a.stdout.readline()
        assert line, "worker A ended early"
        lines_a += line.startswith("commit")
    a.send_signal(signal.SIGSTOP)
    time.sleep(0.2)
    rows_at_stop = count(sf, cid)  # only A wrote so far
    time.sleep(1.5 + 0.5)  # past A's 1.5 s lease
    b = start_worker(migrated_db_url, cid)
    deadline = time.monotonic() + 60
    while count(sf, cid) < rows_at_stop + 5 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert count(sf, cid) >= rows_at_stop + 5, "B did not take the rig over"
    a.send_signal(signal.SIGCONT)  # A wakes up believing it still runs the rig
    time.sleep(2.0)  # A finishes what it was doing; B holds (and renews) the lease meanwhile
    a.send_signal(signal.SIGKILL)
    out_a, _ = a.communicate(timeout=60)
    commits_a = lines_a + sum(1 for ln in out_a.splitlines() if ln.startswith("commit"))
    assert commits_a == rows_at_stop, out_a  # nothing after SIGCONT
    assert "lost the lease" in out_a or "lease no longer held" in out_a, out_a
    b.send_signal(signal.SIGKILL)  # then the new holder dies too
    b.wait()
    c = start_worker(migrated_db_url, cid)
    out_c, _ = c.communicate(timeout=120)
    assert c.returncode == 0, out_c
    with sf() as s:
        c_row = s.get(Campaign, cid)
        assert c_row.state == "completed", (c_row.error, out_c)
        keys = Counter((r[0], r[1]) for r in s.execute(
            select(Measurement.step, Measurement.position)
            .where(Measurement.campaign_id == cid)).all())
    assert set(keys) == {(x, y) for x in range(N_STEPS) for y in range(N_POS)}
    assert max(keys.values()) == 1
