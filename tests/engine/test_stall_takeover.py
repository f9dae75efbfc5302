"""A lease holder stalled past its lease (SIGSTOP) is taken over, and once resumed writes
nothing: three processes on one database, the simulated rig over loopback Modbus/serial.
"""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from collections import Counter

from crash_helpers import N_POS, N_STEPS, SPEC, start_worker
from engine_helpers import add_campaign, n_measurements
from sqlalchemy import select

from service.db.models import Campaign, Measurement

LOST = ("lost the lease", "lease no longer held")


def _read_lines(p: subprocess.Popen, lines: list[str], lost: threading.Event) -> None:
    """Every line ``p`` prints, until it exits; ``lost`` set at its first loss of the lease."""
    assert p.stdout is not None
    for line in p.stdout:
        lines.append(line)
        if any(what in line for what in LOST):
            lost.set()


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
    # B starts at once: it cannot have the rig before A's 1.5 s lease (renewed by A until the
    # stop) has run out, so its start-up overlaps that wait instead of following a sleep.
    b = start_worker(migrated_db_url, cid)
    deadline = time.monotonic() + 60
    while n_measurements(sf, cid) < rows_at_stop + 5 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert n_measurements(sf, cid) >= rows_at_stop + 5, "B did not take the rig over"
    lines: list[str] = []
    lost = threading.Event()
    reader = threading.Thread(target=_read_lines, args=(a, lines, lost), daemon=True)
    reader.start()
    a.send_signal(signal.SIGCONT)  # A wakes up believing it still runs the rig
    # A runs until it finds the lease lost (its renewal, or its next, fenced, commit), and
    # on while B stores five more rows: B holds (and renews) the lease meanwhile.
    assert lost.wait(60), "".join(lines)
    rows_at_loss = n_measurements(sf, cid)
    deadline = time.monotonic() + 60
    while n_measurements(sf, cid) < rows_at_loss + 5 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert n_measurements(sf, cid) >= rows_at_loss + 5, "B stopped after A woke up"
    a.send_signal(signal.SIGKILL)
    a.wait(60)
    reader.join(60)
    out_a = "".join(lines)
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
