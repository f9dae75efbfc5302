"""What reading a campaign costs with the dry run stored at creation, and without.

    .venv/bin/python benchmarks/bench_stored_dry_run.py [--campaigns 40] [--reads 200]

1. Creates ``--campaigns`` campaigns through ``POST /api/v1/campaigns`` on a fresh SQLite
   file (every one a distinct spec: its own setpoints, schedule and order, as a lab's
   campaigns differ), through the whole ASGI stack; the dry run is stored with each.
2. Starts a new app (a restarted service: empty caches) and times the first
   ``GET /campaigns`` (every campaign in one list) and ``--reads`` ``GET /campaigns/{id}``
   spread over the campaigns: the reads use the stored predictions.
3. Clears the stored predictions (``dry_run`` NULL, as rows created before migration
   0008) and repeats 2: the first read plans each distinct spec once (what every service
   start paid before the prediction was stored), the later reads use what it stored.

Prints the times (ms) and checks that both ways give the same predicted_duration_s.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SCHEDULES = ("table1", "six", "cube14", "table1+six", "sphere24", "sphere30")
ORDERS = ("travel", "table", "balanced")


def _spec(i: int) -> dict[str, Any]:
    lo = -40.0 + (i % 5) * 5.0
    return {"rig": "sim", "sensor": f"SN-{i:04d}", "positions": SCHEDULES[i % len(SCHEDULES)],
            "setpoints_c": [lo + 10.0 * k for k in range(6 + i % 6)],
            "position_order": ORDERS[i % len(ORDERS)], "soak_min": 30.0 + i}


def _app(url: str) -> Any:
    from fastapi.testclient import TestClient

    from service.api.app import create_app
    from service.config import Settings

    return TestClient(create_app(Settings(database_url=url, run_engine=False,
                                          run_scheduler=False)))


def _reads(url: str, headers: dict[str, str], ids: list[int], n_reads: int
           ) -> tuple[float, list[float], dict[int, float]]:
    import service.campaigns as campaigns_mod

    campaigns_mod._prediction_of.cache_clear()  # a restarted process
    with _app(url) as client:
        t0 = time.perf_counter()
        listed = client.get("/api/v1/campaigns", headers=headers)
        first_ms = (time.perf_counter() - t0) * 1e3
        assert listed.status_code == 200, listed.text
        got = {c["id"]: c["predicted_duration_s"] for c in listed.json()}
        times = []
        for k in range(n_reads):
            t0 = time.perf_counter()
            one = client.get(f"/api/v1/campaigns/{ids[k % len(ids)]}", headers=headers)
            times.append((time.perf_counter() - t0) * 1e3)
            assert one.status_code == 200
    return first_ms, times, got


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", type=int, default=40)
    ap.add_argument("--reads", type=int, default=200)
    args = ap.parse_args()

    from sqlalchemy import update

    from service.api.auth import create_token
    from service.db.models import Campaign
    from service.db.session import session_scope

    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{tmp}/bench.db"
        with _app(url) as client:
            sf = client.app.state.session_factory  # type: ignore[attr-defined]
            with session_scope(sf) as session:
                op = {"Authorization": f"Bearer {create_token(session, 'operator', 'b')}"}
                viewer = {"Authorization": f"Bearer {create_token(session, 'viewer', 'b')}"}
            t0 = time.perf_counter()
            ids = []
            for i in range(args.campaigns):
                r = client.post("/api/v1/campaigns", json=_spec(i), headers=op)
                assert r.status_code == 201, r.text
                ids.append(r.json()["id"])
            create_ms = (time.perf_counter() - t0) * 1e3 / args.campaigns
        stored_first, stored_reads, stored = _reads(url, viewer, ids, args.reads)
        with _app(url) as client:
            sf = client.app.state.session_factory  # type: ignore[attr-defined]
            with session_scope(sf) as session:
                session.execute(update(Campaign).values(dry_run=None))
        legacy_first, legacy_reads, legacy = _reads(url, viewer, ids, args.reads)
    assert stored == legacy, "the stored and the recomputed predictions differ"
    print(f"{args.campaigns} campaigns (distinct specs), POST with the dry run stored: "
          f"{create_ms:.1f} ms each")
    for name, first, reads in (("stored at creation", stored_first, stored_reads),
                               ("not stored (pre-0008 rows)", legacy_first, legacy_reads)):
        print(f"{name:28s} first GET /campaigns after start {first:8.1f} ms; "
              f"GET /campaigns/{{id}} p50 {statistics.median(reads):5.2f} ms, "
              f"max {max(reads):6.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
