"""What the row fence costs: one runner write, fenced (store.fenced_sessions) and not.

    .venv/bin/python benchmarks/bench_fenced_writes.py [--n 300]
    SOAKCAL_TEST_DATABASE_URL=postgresql+psycopg://postgres@127.0.0.1:5432/test \\
        .venv/bin/python benchmarks/bench_fenced_writes.py [--n 300]

On a migrated database (an SQLite file with the engine's WAL setting; PostgreSQL
in a schema of its own when the URL is set) with one running campaign and this
process holding its rig lease: the median wall time of the runner's most frequent
writes (a progress update, the one written at every poll; a soak probe insert)
and of its most frequent read (``load_campaign``), each ``--n`` times through the
plain session factory and through the fenced one. The fenced write adds one
``UPDATE rig_leases`` (and two ``SET LOCAL`` on PostgreSQL) to its transaction.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import quote

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

PROBE = {"sensor": "SN-B", "step": 0, "soak_start_t_s": 0.0, "pose": "0.0,0.0,0.0",
         "t_s": 5.0, "setpoint_c": -10.0, "chamber_c": -9.0, "sensor_c": -5.0, "ref_x": 0.0,
         "ref_y": 0.0, "ref_z": 1.0, "ax": 0.0, "ay": 0.0, "az": 1.0, "n": 8}


def median_ms(fn: Callable[[int], Any], n: int) -> float:
    for i in range(5):  # warm the pool and the statement caches
        fn(i)
    times = []
    for i in range(n):
        t0 = time.perf_counter()
        fn(i)
        times.append(time.perf_counter() - t0)
    return 1000.0 * statistics.median(times)


def measure(url: str, n: int) -> dict[str, float]:
    from service.db.models import Campaign, Rig
    from service.db.session import make_session_factory, upgrade_database
    from service.engine import store
    from service.engine.manager import CampaignManager

    upgrade_database(url)
    sf = make_session_factory(url)
    store.fast_sqlite_commits(sf)
    with sf() as s:
        s.add(Rig(name="bench", chamber={"driver": "sim"}, turntable={"driver": "sim"},
                  sensors=[]))
        s.flush()
        c = Campaign(rig="bench", sensor="SN-B", spec={}, state="running", progress={},
                     steps_log=[])
        s.add(c)
        s.commit()
        cid = c.id
    assert CampaignManager(sf, owner="bench", lease_s=3600)._claim("bench", cid)
    fenced = store.fenced_sessions(sf, store.Fence("bench", "bench"), cid)
    out: dict[str, float] = {}
    for label, factory in (("plain", sf), ("fenced", fenced)):
        out[f"progress {label}"] = median_ms(
            lambda i, f=factory: store.update_campaign(f, cid, progress={"t_s": float(i)}), n)
        out[f"probe {label}"] = median_ms(
            lambda i, f=factory: store.add_soak_probes(f, cid, [{**PROBE, "t_s": float(i)}]), n)
        out[f"read {label}"] = median_ms(lambda _i, f=factory: store.load_campaign(f, cid), n)
    sf.kw["bind"].dispose()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    args = ap.parse_args()
    base = os.environ.get("SOAKCAL_TEST_DATABASE_URL", "")
    if base.startswith("postgresql"):
        from sqlalchemy import create_engine, text

        schema = f"bench_{uuid.uuid4().hex[:12]}"
        admin = create_engine(base, isolation_level="AUTOCOMMIT")
        with admin.connect() as conn:
            conn.execute(text(f'CREATE SCHEMA "{schema}"'))
        sep = "&" if "?" in base else "?"
        try:
            res = measure(f"{base}{sep}options={quote(f'-csearch_path={schema}')}", args.n)
        finally:
            with admin.connect() as conn:
                conn.execute(text(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE'))
            admin.dispose()
        backend = "postgresql"
    else:
        with tempfile.TemporaryDirectory() as tmp:
            res = measure(f"sqlite:///{tmp}/bench.db", args.n)
        backend = "sqlite"
    print(f"{backend}, n={args.n}, median ms per call")
    for what in ("progress", "probe", "read"):
        plain, fenced = res[f"{what} plain"], res[f"{what} fenced"]
        print(f"{what:8s} plain {plain:6.3f}  fenced {fenced:6.3f}  added {fenced - plain:+6.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
