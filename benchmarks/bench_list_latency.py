"""List latency of the REST service: ``GET /campaigns`` pages and ``GET /rigs`` at scale.

    .venv/bin/python benchmarks/bench_list_latency.py [--campaigns 10000] [--rigs 136]
        [--requests 300] [--page 50] [--database-url URL] [--json PATH]

1. (Re)creates the benchmark database (its name must contain ``bench``: it is dropped),
   migrates it with the service's Alembic migrations, and stores ``--rigs`` rigs and
   ``--campaigns`` campaigns spread over them (every state, realistic specs: a few
   distinct setpoint lists and position schedules, as a lab's campaigns repeat).
2. Builds the service's app in-process (``service.api.app.create_app``, engine and
   scheduler off) and sends, one after the other through the whole ASGI stack (auth,
   door, handler, database), ``--requests`` of each: ``GET /campaigns?limit=PAGE&offset=O``
   (O random over the whole list), the same filtered by ``state``, ``GET /campaigns/{id}``
   and ``GET /rigs``; the first 10 of each are not counted (imports, cold caches).
3. Prints p50/p90/p99/max per request kind (ms) and the load averages: the client
   shares the machine with the service and the database.

The requests are sequential (closed loop): the figures are the service time of one
request, not a throughput under load (benchmarks/bench_query_latency.py does that for
coefficient queries).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

DEFAULT_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/soakcal_bench_list"
STATES = ("completed", "completed", "completed", "failed", "aborted", "queued", "running",
          "paused")
WARMUP = 10


def recreate_database(url: str) -> None:
    from sqlalchemy import create_engine, make_url, text

    parsed = make_url(url)
    name = parsed.database or ""
    if "bench" not in name:
        raise SystemExit(f"refusing to drop database {name!r}: its name must contain 'bench'")
    admin = create_engine(parsed.set(database="postgres"), isolation_level="AUTOCOMMIT")
    try:
        with admin.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
            conn.execute(text(f'CREATE DATABASE "{name}"'))
    finally:
        admin.dispose()


def fill(url: str, n_campaigns: int, n_rigs: int, seed: int = 1) -> None:
    """``n_rigs`` rigs and ``n_campaigns`` campaigns over them, in bulk."""
    import datetime as dt

    from sqlalchemy import insert

    from service.db.models import Campaign, Rig, Sensor
    from service.db.session import make_engine

    rng = random.Random(seed)
    rigs = [{"name": f"rig-{k:03d}", "chamber": {"driver": "sim", "range_c": [-70, 180]},
             "turntable": {"driver": "sim"}, "sensors": [{"driver": "sim"}]}
            for k in range(n_rigs)]
    specs = [{"setpoints_c": sp, "soak_min": soak, "positions": pos,
              "samples_per_position": 200}
             for sp in ([-40.0, -20.0, 0.0, 20.0, 40.0, 60.0], [-40.0 + 10 * i for i in range(11)])
             for soak in (30.0, 60.0) for pos in ("table1", "cube14", "six")]
    start = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    rows = []
    for i in range(n_campaigns):
        rig = rigs[i % n_rigs]["name"]
        state = rng.choice(STATES)
        serial = f"SN-{i % 2000:05d}"
        spec = {**rng.choice(specs), "rig": rig, "sensor": serial}
        created = start + dt.timedelta(minutes=30 * i)
        rows.append({
            "rig": rig, "sensor": serial, "spec": spec, "state": state, "created_at": created,
            "started_at": None if state == "queued" else created,
            "finished_at": created if state in ("completed", "failed", "aborted") else None,
            "progress": {"step": 3, "steps": len(spec["setpoints_c"]), "phase": "soak",
                         "fraction": 0.4, "chamber_c": 20.1, "eta_s": 3600.0},
            "steps_log": []})
    engine = make_engine(url)
    try:
        with engine.begin() as conn:
            conn.execute(insert(Rig), rigs)
            conn.execute(insert(Sensor), [{"serial": f"SN-{k:05d}", "model": "ADXL355",
                                           "created_at": start} for k in range(2000)])
            for lo in range(0, len(rows), 2000):
                conn.execute(insert(Campaign), rows[lo:lo + 2000])
    finally:
        engine.dispose()


def percentiles(ms: list[float]) -> dict[str, float]:
    ordered = sorted(ms)

    def q(p: float) -> float:
        return ordered[min(len(ordered) - 1, int(round(p * (len(ordered) - 1))))]

    return {"n": len(ordered), "p50_ms": round(statistics.median(ordered), 2),
            "p90_ms": round(q(0.90), 2), "p99_ms": round(q(0.99), 2),
            "max_ms": round(ordered[-1], 2)}


def measure(url: str, n_campaigns: int, n_requests: int, page: int) -> dict[str, Any]:
    from fastapi.testclient import TestClient

    from service.api.app import create_app
    from service.api.auth import create_token
    from service.config import Settings
    from service.db.session import session_scope

    app = create_app(Settings(database_url=url, run_engine=False, run_scheduler=False,
                              migrate=False, seed_sim_rig=False))
    rng = random.Random(2)
    with TestClient(app) as client:
        with session_scope(app.state.session_factory) as session:
            token = create_token(session, "viewer", "bench")
        headers = {"Authorization": f"Bearer {token}"}
        kinds = {
            f"GET /campaigns?limit={page}&offset=random": lambda: client.get(
                "/api/v1/campaigns", headers=headers,
                params={"limit": page, "offset": rng.randrange(max(n_campaigns - page, 1))}),
            f"GET /campaigns?state=completed&limit={page}&offset=random": lambda: client.get(
                "/api/v1/campaigns", headers=headers,
                params={"state": "completed", "limit": page,
                        "offset": rng.randrange(max(n_campaigns // 3 - page, 1))}),
            "GET /campaigns/{id}": lambda: client.get(
                f"/api/v1/campaigns/{rng.randrange(1, n_campaigns + 1)}", headers=headers),
            "GET /rigs": lambda: client.get("/api/v1/rigs", headers=headers),
        }
        out: dict[str, Any] = {}
        for kind, send in kinds.items():
            times: list[float] = []
            for i in range(n_requests + WARMUP):
                t0 = time.perf_counter()
                response = send()
                elapsed_ms = (time.perf_counter() - t0) * 1e3
                if response.status_code != 200:
                    raise SystemExit(f"{kind}: HTTP {response.status_code}: {response.text}")
                if i >= WARMUP:
                    times.append(elapsed_ms)
            out[kind] = percentiles(times)
    app.state.engine.dispose()
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--campaigns", type=int, default=10_000)
    parser.add_argument("--rigs", type=int, default=136)
    parser.add_argument("--requests", type=int, default=300)
    parser.add_argument("--page", type=int, default=50)
    parser.add_argument("--database-url", default=os.environ.get("BENCH_DATABASE_URL",
                                                                 DEFAULT_URL))
    parser.add_argument("--json", metavar="PATH", help="also write the figures as JSON")
    args = parser.parse_args()

    from service.db.session import upgrade_database

    t0 = time.perf_counter()
    recreate_database(args.database_url)
    upgrade_database(args.database_url)
    fill(args.database_url, args.campaigns, args.rigs)
    print(f"stored {args.campaigns} campaigns on {args.rigs} rigs in "
          f"{time.perf_counter() - t0:.1f} s")
    result = {"campaigns": args.campaigns, "rigs": args.rigs, "page": args.page,
              "latency": measure(args.database_url, args.campaigns, args.requests, args.page),
              "loadavg": [round(v, 2) for v in os.getloadavg()]}
    for kind, figures in result["latency"].items():
        print(f"{kind:<55} p50 {figures['p50_ms']:7.1f} ms  p90 {figures['p90_ms']:7.1f}  "
              f"p99 {figures['p99_ms']:7.1f}  max {figures['max_ms']:7.1f}  (n={figures['n']})")
    print(f"load averages {result['loadavg']}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
