"""A lease holder stalled with SIGSTOP, three workers, one PostgreSQL, one shared twin.

    SOAKCAL_TEST_DATABASE_URL=postgresql+psycopg://postgres@127.0.0.1:5432/test \\
        .venv/bin/python benchmarks/bench_stall.py [--speed 200] [--lease-s 6] \\
        [--scenarios between,in-commit,before-probe,mid-move]

One twin (Modbus chamber and table servers, sensor bridge; ScaledClock at
``--speed``) runs in its own process; three worker processes (CampaignManager
with the rig as a ``modbus`` rig at those URLs, the service's real drivers) share
one PostgreSQL schema and the one rig. Four scenarios, each a fresh campaign:

* ``between``: worker A is SIGSTOPped just after a measurement commit (outside
  any transaction), for 2 lease periods, then SIGCONTed;
* ``in-commit``: A is SIGSTOPped inside a fenced commit (its lease row locked;
  the worker holds the transaction open 0.5 s so the stop lands in it);
* ``before-probe``: A is SIGSTOPped in a soak between a die probe's capture and
  its row (the worker holds each probe write 0.5 s before its transaction): on
  resume its next act is a database write, not a device command;
* ``mid-move``: A is SIGSTOPped between a table move's two write requests (the
  targets, then the move command; the worker holds 0.5 s between them).

Each worker logs every rig-changing command as it reaches the driver (below the
device fence) with its wall time, and the largest stall of its event loop
(a 50 ms ticker: the HTTP API shares this loop in ``soakcal serve``). Reported
per scenario: commands A sent after it resumed (must be 0), its Modbus write
requests and its committed row writes (other than the lease's) after it resumed
(both must be 0), takeover time
(the stop to the lease claim by another worker: one lease period, plus a scan,
is the aim) and to the first commit by another worker (the claim plus opening
the rig, re-ramp and the resumed step's re-check), the largest event-loop stall
of the workers that did not stop, from the stop to 2 s after the resume (an API
on that loop would not have answered for that long), whether the campaign
completed, and captures stored more than 15° from their label (must be 0).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any
from urllib.parse import quote

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

SPEC = {"setpoints_c": [0.0, 20.0, 40.0], "soak_min": 10, "positions": "six",
        "samples_per_position": 50, "ramp_c_per_min": 2.0}
MUTATING = {"ModbusChamber": ("set_setpoint", "set_ramp_rate", "run", "stop"),
            "ModbusTurntable": ("move_to", "stop")}


# --- the twin process -------------------------------------------------------------
async def _twin(base_port: int, speed: float) -> None:
    from drivers.clock import ScaledClock
    from simulators.rig import start_sim_rig

    async with start_sim_rig(ScaledClock(speed), seed=3, ports=base_port) as sim:
        print("twin", sim.chamber_url, sim.table_url, sim.sensor_url, sim.chamber_map, flush=True)
        await asyncio.Event().wait()


# --- a worker process ---------------------------------------------------------------
def _log_commands() -> None:
    """Print every rig-changing command as it reaches the driver (after the fence)."""
    from drivers import chamber, turntable

    for module, (cls_name, names) in ((chamber, ("ModbusChamber", MUTATING["ModbusChamber"])),
                                      (turntable, ("ModbusTurntable",
                                                   MUTATING["ModbusTurntable"]))):
        cls = getattr(module, cls_name)
        for name in names:
            inner = getattr(cls, name)

            async def logged(self: Any, *args: Any, _inner: Any = inner,
                             _label: str = f"{cls_name}.{name}") -> Any:
                print(f"cmd {time.time():.3f} {_label} {args}", flush=True)
                return await _inner(self, *args)

            setattr(cls, name, logged)


def _log_wire_writes_and_rows() -> None:
    """Print every Modbus write request as its bytes are about to leave (after the device
    fence and the link's per-write fence: a write refused there is not printed), and
    every committed transaction that wrote a row other than the lease's."""
    from sqlalchemy import event
    from sqlalchemy.engine import Engine

    from drivers.modbus_link import ModbusLink

    request = ModbusLink._request

    async def logged_request(self: Any, what: str, address: int, call: Any,
                             *args: Any, **kwargs: Any) -> Any:
        if what != "write":
            return await request(self, what, address, call, *args, **kwargs)

        async def sent(client: Any) -> Any:
            print(f"wreq {time.time():.3f} {self.device} {address}", flush=True)
            return await call(client)

        return await request(self, what, address, sent, *args, **kwargs)

    ModbusLink._request = logged_request  # type: ignore[method-assign]

    def dml(conn: Any, _cursor: Any, statement: str, *_a: Any) -> None:
        verb = statement.lstrip().split(None, 1)[0].upper() if statement.strip() else ""
        if verb in ("INSERT", "UPDATE", "DELETE") and "rig_leases" not in statement:
            conn.info["wrote"] = statement.split("(")[0][:40]

    def commit(conn: Any) -> None:
        wrote = conn.info.pop("wrote", None)
        if wrote:
            print(f"rowwrite {time.time():.3f} {wrote}", flush=True)

    event.listen(Engine, "before_cursor_execute", dml)
    event.listen(Engine, "commit", commit)
    event.listen(Engine, "rollback", lambda conn: conn.info.pop("wrote", None))


def _stall_before_probes() -> None:
    """Hold each soak probe's write 0.5 s before its transaction, so a stop lands between
    the capture (a read) and the row it makes."""
    from service.engine import store

    add = store.add_soak_probes

    def slow_add(*args: Any, **kwargs: Any) -> None:
        print(f"pre-probe {time.time():.3f}", flush=True)
        time.sleep(0.5)
        add(*args, **kwargs)

    store.add_soak_probes = slow_add  # type: ignore[assignment]


def _stall_mid_move() -> None:
    """Hold 0.5 s after each table move's first write (the targets, several words) and
    before its second (the move command), so a stop lands between the two."""
    from drivers.modbus_link import ModbusLink

    write = ModbusLink.write_registers

    async def slow_write(self: Any, address: int, words: list[int], **kwargs: Any) -> None:
        await write(self, address, words, **kwargs)
        if self.device == "turntable" and len(words) > 1:
            print(f"mid-move {time.time():.3f}", flush=True)
            time.sleep(0.5)

    ModbusLink.write_registers = slow_write  # type: ignore[method-assign]


def _log_commits(stall_in_commit: bool) -> None:
    from service.engine import store

    commit = store.commit_measurements
    check = store._check_fence

    measuring = [False]  # inside commit_measurements (every fenced write checks the lease)

    def reporting(*args: Any, **kwargs: Any) -> bool:
        measuring[0] = True
        try:
            stored = commit(*args, **kwargs)
        finally:
            measuring[0] = False
        if stored:
            print(f"commit {time.time():.3f}", flush=True)
        return stored

    def slow_check(s: Any, fence: Any, campaign_id: int) -> None:
        check(s, fence, campaign_id)
        if measuring[0]:
            print(f"in-commit {time.time():.3f}", flush=True)
            time.sleep(0.5)  # hold the lease row's lock long enough to be stopped inside

    store.commit_measurements = reporting  # type: ignore[assignment]
    if stall_in_commit:
        store._check_fence = slow_check  # type: ignore[assignment]


_TICK = [time.monotonic()]


def _watch_loop_stalls() -> None:
    """Diagnostics: print the loop thread's stack when it has not ticked for 0.5 s."""
    import traceback

    main_id = threading.get_ident()

    async def tick() -> None:
        while True:
            _TICK[0] = time.monotonic()
            await asyncio.sleep(0.05)

    asyncio.get_running_loop().create_task(tick())

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if time.monotonic() - _TICK[0] > 0.5:
                frame = sys._current_frames().get(main_id)
                here = traceback.format_stack(frame) if frame else []
                stack = "".join([ln for ln in here if f"{ROOT}/service" in ln][:6])
                print("stall-stack", stack.replace("\n", " | "), flush=True)

    threading.Thread(target=watch, daemon=True).start()


async def _worker(url: str, lease_s: float, stall_in_commit: bool,
                  stall_before_probe: bool = False, stall_mid_move: bool = False) -> None:
    from service.db.session import make_session_factory
    from service.engine.manager import CampaignManager

    _log_commands()
    _log_wire_writes_and_rows()
    _log_commits(stall_in_commit)
    if stall_before_probe:
        _stall_before_probes()
    if stall_mid_move:
        _stall_mid_move()
    sf = make_session_factory(url)
    mgr = CampaignManager(sf, lease_s=lease_s, poll_wall_s=0.2, owner=f"w{os.getpid()}")
    claim = mgr._claim

    def reporting_claim(rig: str, campaign_id: int) -> bool:
        won = claim(rig, campaign_id)
        if won:
            print(f"claim {time.time():.3f}", flush=True)
        return won

    mgr._claim = reporting_claim  # type: ignore[method-assign]

    async def ticker() -> None:
        worst = 0.0
        last = time.monotonic()
        while True:
            await asyncio.sleep(0.05)
            now = time.monotonic()
            lag = now - last - 0.05
            if lag > 0.1:  # every stall of the loop longer than 0.1 s, when it ended
                print(f"lag {time.time():.3f} {lag:.3f}", flush=True)
            worst = max(worst, lag)
            last = now

    tick = asyncio.create_task(ticker())
    if os.environ.get("BENCH_STALL_VERBOSE"):
        _watch_loop_stalls()
    await mgr.start()
    await asyncio.sleep(0.5)
    print(f"ready {time.time():.3f}", flush=True)
    try:
        await asyncio.Event().wait()
    finally:
        tick.cancel()
        await mgr.stop()


# --- the bench ------------------------------------------------------------------------
class Proc:
    """A child process whose stdout lines are kept with their arrival (wall) time."""

    def __init__(self, name: str, argv: list[str]) -> None:
        self.name = name
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        self.p = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            self.lines.append(line.rstrip())

    def stamped(self, kind: str) -> list[float]:
        return [float(ln.split()[1]) for ln in list(self.lines) if ln.startswith(kind + " ")]

    def wait_line(self, kind: str, n: int = 1, timeout_s: float = 120.0) -> None:
        deadline = time.monotonic() + timeout_s
        while len(self.stamped(kind)) < n:
            if time.monotonic() > deadline or self.p.poll() is not None:
                raise RuntimeError(f"{self.name}: no {n} '{kind}' lines:\n"
                                   + "\n".join(self.lines[-30:]))
            time.sleep(0.005)

    def kill(self) -> None:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGCONT)
            self.p.kill()
            self.p.wait()


def _schema_url(base: str) -> tuple[str, Any]:
    from sqlalchemy import create_engine, text

    schema = f"bench_{uuid.uuid4().hex[:12]}"
    admin = create_engine(base, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    sep = "&" if "?" in base else "?"
    return f"{base}{sep}options={quote(f'-csearch_path={schema}')}", (admin, schema)


def _drop_schema(admin: Any, schema: str) -> None:
    from sqlalchemy import text

    with admin.connect() as conn:
        conn.execute(text("SET lock_timeout = '5s'"))
        conn.execute(text(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE'))
    admin.dispose()


def scenario(name: str, base: str, urls: list[str], speed: float, lease_s: float) -> dict:
    import numpy as np
    from sqlalchemy import select

    from calibration.placement import MAX_ANGLE_DEG, direction_error_deg
    from service.db.models import Campaign, Measurement, Rig
    from service.db.session import make_session_factory, upgrade_database

    url, (admin, schema) = _schema_url(base)
    upgrade_database(url)
    sf = make_session_factory(url)
    with sf() as s:
        s.add(Rig(name="lab", chamber={"driver": "modbus", "url": urls[0], "map": urls[3],
                                       "range_c": [-40, 85], "time_scale": speed},
                  turntable={"url": urls[1], "axes": 3},
                  sensors=[{"url": urls[2], "serial_binding": "any"}]))
        s.flush()
        c = Campaign(rig="lab", sensor="SN-STALL", spec=dict(SPEC), state="queued",
                     progress={}, steps_log=[])
        s.add(c)
        s.commit()
        cid = c.id
    me = str(Path(__file__).resolve())
    in_commit = name == "in-commit"
    argv = [sys.executable, me, "--worker", url, "--lease-s", str(lease_s)]
    a = Proc("A", argv + (["--stall-in-commit"] if in_commit else [])
             + (["--stall-before-probe"] if name == "before-probe" else [])
             + (["--stall-mid-move"] if name == "mid-move" else []))
    a.wait_line("commit", 1, timeout_s=300)
    b = Proc("B", argv)
    c_ = Proc("C", argv)
    b.wait_line("ready")
    c_.wait_line("ready")
    if in_commit:
        n = len(a.stamped("in-commit"))
        a.wait_line("in-commit", n + 1)
    elif name in ("before-probe", "mid-move"):
        kind = "pre-probe" if name == "before-probe" else "mid-move"
        n = len(a.stamped(kind))
        a.wait_line(kind, n + 1, timeout_s=300)
    else:
        n = len(a.stamped("commit"))
        a.wait_line("commit", n + 1)
    a.p.send_signal(signal.SIGSTOP)
    stopped = time.time()
    deadline = time.monotonic() + 10 * lease_s
    while time.monotonic() < deadline:
        claims = [t for p in (b, c_) for t in p.stamped("claim") if t > stopped]
        if claims:
            break
        time.sleep(0.01)
    takeover_s = (min(claims) - stopped) if claims else float("nan")
    time.sleep(max(0.0, stopped + 2 * lease_s - time.time()))
    a.p.send_signal(signal.SIGCONT)
    resumed = time.time()
    finished = False
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        with sf() as s:
            state = s.get(Campaign, cid).state
        if state in ("completed", "failed", "aborted"):
            finished = True
            break
        time.sleep(0.2)
    time.sleep(1.0)
    def after_resume(kind: str) -> list[str]:
        return [ln for ln in a.lines if ln.startswith(kind + " ")
                and float(ln.split()[1]) > resumed]

    cmds_after = after_resume("cmd")
    wire_after, rows_after = after_resume("wreq"), after_resume("rowwrite")
    # The loop stalls of the workers that kept running, from the stop to 2 s after the
    # resume: the time an API on their loop would not have answered during the failover.
    lag_others = max([0.0] + [float(ln.split()[2]) for p in (b, c_) for ln in p.lines
                              if ln.startswith("lag ")
                              and stopped <= float(ln.split()[1]) <= resumed + 2.0])
    first_commit_s = min([t for p in (b, c_) for t in p.stamped("commit") if t > stopped]
                         or [float("nan")]) - stopped
    if os.environ.get("BENCH_STALL_VERBOSE"):
        for p in (b, c_):
            for ln in p.lines:
                if ln.split()[0] in ("lag", "claim", "commit") and float(ln.split()[1]) > stopped:
                    print(p.name, ln.split()[0], f"{float(ln.split()[1]) - stopped:+.2f}",
                          *ln.split()[2:])
        print("resumed", f"{resumed - stopped:+.2f}")
        for p in (b, c_):
            print("\n".join(ln for ln in p.lines if ln.startswith("stall-stack")))
    for p in (a, b, c_):
        p.kill()
    with sf() as s:
        camp = s.get(Campaign, cid)
        rows = s.execute(select(Measurement.ax, Measurement.ay, Measurement.az, Measurement.ref_x,
                                Measurement.ref_y, Measurement.ref_z)
                         .where(Measurement.campaign_id == cid)).all()
        out = {"scenario": name, "state": camp.state if finished else "timeout",
               "error": camp.error, "rows": len(rows),
               "wrong_pose": sum(direction_error_deg(np.array(r[:3]), np.array(r[3:]))
                                 >= MAX_ANGLE_DEG for r in rows),
               "commands_after_resume": len(cmds_after), "takeover_s": takeover_s,
               "write_requests_after_resume": len(wire_after),
               "row_writes_after_resume": len(rows_after),
               # A's before the stop: the probes above see what they count
               "a_write_requests": len(a.stamped("wreq")), "a_row_writes": len(a.stamped(
                   "rowwrite")),
               "first_commit_s": first_commit_s,
               "lease_s": lease_s, "max_loop_stall_s": lag_others}
    sf.kw["bind"].dispose()
    _drop_schema(admin, schema)
    for lines in (cmds_after, wire_after, rows_after):
        if lines:
            print("\n".join(lines[:10]))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=200.0)
    ap.add_argument("--lease-s", type=float, default=6.0)
    ap.add_argument("--port", type=int, default=15620)
    ap.add_argument("--worker", metavar="DB_URL")
    ap.add_argument("--scenarios", default="between,in-commit,before-probe,mid-move",
                    help="comma-separated: between, in-commit, before-probe, mid-move")
    ap.add_argument("--stall-in-commit", action="store_true")
    ap.add_argument("--stall-before-probe", action="store_true")
    ap.add_argument("--stall-mid-move", action="store_true")
    ap.add_argument("--twin", action="store_true")
    args = ap.parse_args()
    if args.twin:
        asyncio.run(_twin(args.port, args.speed))
        return 0
    if args.worker:
        asyncio.run(_worker(args.worker, args.lease_s, args.stall_in_commit,
                            args.stall_before_probe, args.stall_mid_move))
        return 0
    base = os.environ.get("SOAKCAL_TEST_DATABASE_URL", "")
    if not base.startswith("postgresql"):
        print("bench_stall: set SOAKCAL_TEST_DATABASE_URL to a PostgreSQL URL", file=sys.stderr)
        return 2
    results = []
    ap_names = ("between", "in-commit", "before-probe", "mid-move")
    for name in [n for n in ap_names if n in args.scenarios.split(",")]:
        twin = Proc("twin", [sys.executable, str(Path(__file__).resolve()), "--twin",
                             "--port", str(args.port), "--speed", str(args.speed)])
        try:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                ready = [ln for ln in list(twin.lines) if ln.startswith("twin ")]
                if ready:
                    break
                time.sleep(0.05)
            urls = ready[0].split()[1:5]
            results.append(scenario(name, base, urls, args.speed, args.lease_s))
        finally:
            twin.kill()
    print(f"speed {args.speed:g}x, lease {args.lease_s:g} s, spec {SPEC}")
    print("scenario   state      rows  cmds_after_resume  wire_writes_after  "
          "row_writes_after  takeover_s  first_commit_s  max_loop_stall_s  wrong_pose")
    for r in results:
        print(f"{r['scenario']:10s} {r['state']:10s} {r['rows']:4d}  "
              f"{r['commands_after_resume']:17d}  {r['write_requests_after_resume']:17d}  "
              f"{r['row_writes_after_resume']:16d}  {r['takeover_s']:10.2f}  "
              f"{r['first_commit_s']:14.2f}  "
              f"{r['max_loop_stall_s']:16.3f}  {r['wrong_pose']:10d}"
              + (f"  error: {r['error']}" if r["error"] else ""))
    for r in results:
        print(f"{r['scenario']}: A sent {r['a_write_requests']} Modbus write requests and "
              f"committed {r['a_row_writes']} row-writing transactions in all")
    ok = all(r["state"] == "completed" and r["commands_after_resume"] == 0
             and r["write_requests_after_resume"] == 0 and r["row_writes_after_resume"] == 0
             and r["wrong_pose"] == 0 and r["takeover_s"] <= r["lease_s"] + 2.0
             for r in results)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
