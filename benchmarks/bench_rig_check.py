"""``soakcal rig check --move`` against ``soakcal sim`` serving each shipped chamber map.

For every shipped chamber map, and for the map file the test suite writes from
the TestEquity F4T manual alone (tests/drivers/test_rig_check.py), this starts
``soakcal sim --chamber-map MAP`` as its own process (real time, Modbus TCP
and the sensor bridge on loopback), registers a ``modbus`` rig pointing at it
in a scratch SQLite database, runs ``soakcal rig check NAME --move --json``
as a process (and once without ``--move``), and tabulates exit code,
pass/fail/skip counts and wall time; the last column times the read-only
checks alone, called in this process against the same ``soakcal sim``.

    .venv/bin/python benchmarks/bench_rig_check.py
"""

from __future__ import annotations

import asyncio
import importlib.util
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from drivers.registermaps import CHAMBER_MAPS
from service.rig_check import check_rig, passed

ROOT = Path(__file__).resolve().parents[1]
SOAKCAL = str(Path(sys.executable).with_name("soakcal"))


def doc_only_map(tmp: Path) -> Path:
    """The map text the test writes from the documentation alone, as a file."""
    spec = importlib.util.spec_from_file_location(
        "test_rig_check", ROOT / "tests" / "drivers" / "test_rig_check.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    path = tmp / "testequity-f4t-cascade.toml"
    path.write_text(mod.F4T_CASCADE)
    return path


def start_sim(chamber_map: str,
              env: dict[str, str]) -> tuple[subprocess.Popen[str], dict[str, str]]:
    proc = subprocess.Popen([SOAKCAL, "sim", "--chamber-map", chamber_map, "--seed", "3"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    urls: dict[str, str] = {}
    assert proc.stdout is not None
    for line in proc.stdout:
        m = re.match(r"\s+(chamber|table|sensor)\s+(?:modbus|serial)\s+(\S+)", line)
        if m:
            urls[m.group(1)] = m.group(2)
        if len(urls) == 3:
            return proc, urls
    raise RuntimeError(f"soakcal sim exited: {proc.stderr.read() if proc.stderr else ''}")


def register(db_url: str, name: str, chamber_map: str,
             urls: dict[str, str]) -> dict[str, object]:
    from service.db.models import Rig
    from service.db.session import make_session_factory, session_scope, upgrade_database
    from service.engine.rigs import rig_config_errors

    chamber = {"driver": "modbus", "url": urls["chamber"], "map": chamber_map, "time_scale": 1}
    table = {"url": urls["table"], "map": "soakcal-table"}
    sensors = [{"url": urls["sensor"]}]
    assert not rig_config_errors(chamber, table, sensors)
    upgrade_database(db_url)
    factory = make_session_factory(db_url)
    with session_scope(factory) as session:
        session.add(Rig(name=name, chamber=chamber, turntable=table, sensors=sensors))
    factory.kw["bind"].dispose()
    return {"name": name, "chamber": chamber, "turntable": table, "sensors": sensors}


def main() -> int:
    rows = []
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        db_url = f"sqlite:///{tmp / 'bench.db'}"
        env = {**os.environ, "SOAKCAL_DATABASE_URL": db_url}
        maps = [*sorted(CHAMBER_MAPS), str(doc_only_map(tmp))]
        for i, chamber_map in enumerate(maps):
            name = f"bench-{i}"
            proc, urls = start_sim(chamber_map, env)
            try:
                rig = register(db_url, name, chamber_map, urls)
                # The checks alone, in this process: what the CLI adds is start-up.
                t0 = time.perf_counter()
                in_process = asyncio.run(check_rig(rig))
                in_process_s = time.perf_counter() - t0
                assert passed(in_process)
                t0 = time.perf_counter()
                read_only = subprocess.run([SOAKCAL, "rig", "check", name], capture_output=True,
                                           text=True, env=env, timeout=170)
                read_only_s = time.perf_counter() - t0
                t0 = time.perf_counter()
                done = subprocess.run([SOAKCAL, "rig", "check", name, "--move", "--json"],
                                      capture_output=True, text=True, env=env, timeout=170)
                wall_s = time.perf_counter() - t0
            finally:
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=10)
            report = json.loads(done.stdout)
            counts = {s: sum(c["status"] == s for c in report["checks"])
                      for s in ("pass", "fail", "skip")}
            skipped = [f"{c['device']}.{c['check']}" for c in report["checks"]
                       if c["status"] != "pass"]
            label = Path(chamber_map).name if "/" in chamber_map else chamber_map
            rows.append((label, done.returncode, counts, wall_s, skipped, read_only.returncode,
                         read_only_s, in_process_s))
    print("| chamber map | exit --move | pass | fail | skip | not passed | wall s --move "
          "| exit, wall s without --move | checks alone in process, s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, code, c, wall_s, skipped, ro_code, ro_s, ip_s in rows:
        print(f"| {label} | {code} | {c['pass']} | {c['fail']} | {c['skip']} | "
              f"{', '.join(skipped) or '–'} | {wall_s:.1f} | {ro_code}, {ro_s:.1f} | "
              f"{ip_s:.2f} |")
    return 0 if all(r[1] == 0 and r[5] == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
