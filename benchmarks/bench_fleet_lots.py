"""Lot statistics (``GET /api/v1/fleet/lots``) over many stored calibrations on PostgreSQL.

    .venv/bin/python benchmarks/bench_fleet_lots.py [--calibrations 10000] [--sensors 10000]
        [--repeats 5] [--database-url URL]

(Re)creates the benchmark database (its name must contain ``bench``), migrates it, stores
``--calibrations`` real-format calibrations over ``--sensors`` sensors (the seeding of
``bench_query_latency.py``: one simulated campaign's fitted model, varied by
datasheet-sized spreads; stored with ``COPY``, so their ``calibration_parameters`` rows are
then backfilled as migration 0007 does for an existing database, and timed), then asks the
service in-process (FastAPI TestClient, the real app and database) for the lot statistics
``--repeats`` times and prints each time, the median, the lot's size and the number of
sensors flagged beyond 4 σ.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_query_latency import (  # noqa: E402
    DEFAULT_DATABASE_URL,
    recreate_database,
    seed_calibrations,
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calibrations", type=int, default=10_000)
    parser.add_argument("--sensors", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--database-url", default=DEFAULT_DATABASE_URL)
    args = parser.parse_args(argv)

    from fastapi.testclient import TestClient

    from service.api.app import create_app
    from service.api.auth import create_token
    from service.config import Settings
    from service.db.calibration_parameters import backfill
    from service.db.session import make_engine, session_scope, upgrade_database

    recreate_database(args.database_url)
    upgrade_database(args.database_url)
    seeded = seed_calibrations(args.database_url, args.calibrations, args.sensors, seed=7)
    print(f"stored {args.calibrations} calibrations over {args.sensors} sensors "
          f"(fit {seeded['fit_s']:.1f} s, store {seeded['store_s']:.1f} s)")
    engine = make_engine(args.database_url)
    t0 = time.perf_counter()
    with engine.begin() as conn:
        filled = backfill(conn)
        conn.exec_driver_sql("ANALYZE calibration_parameters")
    engine.dispose()
    print(f"backfilled the parameters of {filled} calibrations in "
          f"{time.perf_counter() - t0:.1f} s")
    settings = Settings(database_url=args.database_url, run_engine=False, run_scheduler=False,
                        migrate=False, seed_sim_rig=False)
    with TestClient(create_app(settings)) as client:
        with session_scope(client.app.state.session_factory) as session:  # type: ignore[attr-defined]
            token = create_token(session, "viewer", "bench")
        headers = {"Authorization": f"Bearer {token}"}
        times_s = []
        body = {}
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            response = client.get("/api/v1/fleet/lots", headers=headers)
            times_s.append(time.perf_counter() - t0)
            assert response.status_code == 200, response.text
            body = response.json()
    for lot in body["lots"]:
        print(f"lot {lot['model']}: {lot['sensors']} sensors, {len(lot['left_out'])} left out, "
              f"{len(lot['flags'])} flags beyond 4 sigma")
    print("GET /api/v1/fleet/lots: " + ", ".join(f"{t:.2f}" for t in times_s)
          + f" s; median {statistics.median(times_s):.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
