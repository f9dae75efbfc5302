"""A lease holder stalled past its lease (SIGSTOP) is taken over, and once resumed writes
nothing: three processes on one database, the simulated rig over loopback Modbus/serial.
"""

from __future__ import annotations

import signal
import time
from collections import Counter

from crash_helpers import N_POS, N_STEPS, SPEC, start_worker
from engine_helpers import add_campaign, n_measurements
from sqlalchemy import select

from service.db.models import Campaign, Measurement


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
    rows_at_stop = n_measurements(sf, cid)  # only A wrote so far
    time.sleep(1.5 + 0.5)  # past A's 1.5 s lease
    b = start_worker(migrated_db_url, cid)
    deadline = time.monotonic() + 60
    while n_measurements(sf, cid) < rows_at_stop + 5 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert n_measurements(sf, cid) >= rows_at_stop + 5, "B did not take the rig over"
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
