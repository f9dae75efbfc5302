"""Coefficient query latency of the real service on PostgreSQL, under an open-loop load.

    .venv/bin/python benchmarks/bench_query_latency.py [--calibrations 10000] [--sensors 500]
        [--rate 200] [--duration-s 60] [--warmup-s 5] [--connections 32] [--client raw|httpx]
        [--database-url URL] [--json PATH]

What it does:

1. (Re)creates the benchmark database (its name must contain ``bench``: it is dropped)
   and migrates it with the service's own Alembic migrations.
2. Simulates one soak campaign (``simulators.campaign_sim``), fits it with the
   service's fitting path (``service.engine.calibrate.calibrate_columns``), then stores
   ``--calibrations`` variants of that real model document with perturbed polynomial
   coefficients, spread over ``--sensors`` sensors and a year of ``created_at``, via
   ``COPY`` (seconds, not minutes). Every document is a genuine ``dump_model_dict``
   (~15 kB, plus the real fit report). Rows have no campaign (``campaign_id`` NULL).
3. Starts ``soakcal serve`` (the real CLI: migrations, campaign engine, scheduler, uvicorn
   with its access log, here to a temporary file) as a subprocess on a free port, waits
   for ``GET /api/v1/health`` and creates a viewer token with
   ``service.api.auth.create_token``.
4. Drives ``GET /api/v1/sensors/{serial}/coefficients?temperature_c=T`` open-loop: request
   *i* is due at ``t0 + i / rate`` whatever happened to earlier ones (random sensor,
   random T inside every sensor's valid range), and waits in a queue for one of
   ``--connections`` client workers (one keep-alive connection each). Latency runs from
   the *due* time to the end of the response, so all queueing -- for a client worker,
   in the server's accept queue, its thread pool or the database pool -- is counted (no
   coordinated omission). Before ``t0`` each worker sends 3 requests (connection set-up,
   the service's lazy imports); requests due in the first ``--warmup-s`` are not counted.
   The service's model cache is warm for the measured window when ``--sensors`` is at
   most its size (``service.api.coefficients.DEFAULT_CACHE_ENTRIES``).
5. Prints p50/p90/p99/p99.9/max latency (ms), the achieved rate, non-200 responses and
   transport errors, wrong answers (a calibration_id other than the sensor's newest),
   the service's CPU per request, database connections opened during the run, the
   client's own lateness, and the load averages (``os.getloadavg``, as ``uptime``).

The client runs on the same machine as the service and the database, so its CPU
competes with theirs; the figures include that. The default ``raw`` client (HTTP/1.1
on asyncio streams) costs ~0.3 ms of CPU per request, ``httpx`` ~1.6 ms; the
scheduler's lateness is reported so a starved client is visible.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import datetime as dt
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

DEFAULT_DATABASE_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/soakcal_bench"
COEFFICIENTS_PATH = "/api/v1/sensors/{serial}/coefficients"
HEALTH_PATH = "/api/v1/health"
SERIAL_FORMAT = "SN-B{:05d}"
HISTORY_DAYS = 365.0


# --- database -----------------------------------------------------------------
def libpq_conninfo(database_url: str, database: str | None = None) -> str:
    """The SQLAlchemy URL as a libpq URI (optionally for another database on the server)."""
    from sqlalchemy import make_url

    url = make_url(database_url).set(drivername="postgresql")
    if database is not None:
        url = url.set(database=database)
    return url.render_as_string(hide_password=False)


def recreate_database(database_url: str) -> None:
    """Drop and create the benchmark database; refuses names without ``bench`` in them."""
    import psycopg
    from psycopg import sql
    from sqlalchemy import make_url

    url = make_url(database_url)
    if url.get_backend_name() != "postgresql":
        raise SystemExit(f"--database-url must be PostgreSQL, got {url.get_backend_name()}")
    name = url.database or ""
    if "bench" not in name:
        raise SystemExit(
            f"refusing to drop database {name!r}: the benchmark database's name must contain "
            "'bench' (it is dropped and recreated on every run)"
        )
    with psycopg.connect(libpq_conninfo(database_url, "postgres"), autocommit=True) as conn:
        ident = sql.Identifier(name)
        conn.execute(sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(ident))
        conn.execute(sql.SQL("CREATE DATABASE {}").format(ident))


def real_model() -> tuple[Any, dict[str, Any], float]:
    """One fitted ThermalModel from a simulated 11-step campaign, its report, its RMSE (µg)."""
    from calibration.model_file import load_model_dict
    from service.engine.calibrate import calibrate_columns
    from simulators.campaign_sim import simulate_campaign
    from simulators.truth import SensorTruth

    recording = simulate_campaign(SensorTruth.adxl355_typical(seed=1), seed=1)
    columns = {k: [float(v) for v in col] for k, col in recording.columns.items()}
    values = calibrate_columns(columns, {"recording": "bench-campaign.csv"})
    return load_model_dict(values.model), values.report, float(values.rmse_ug)


def model_variants(model: Any, n: int, rng: np.random.Generator) -> Iterator[Any]:
    """``n`` copies of ``model`` with sensor-to-sensor-sized changes to its coefficients.

    The constant terms move by datasheet-sized spreads (bias ±10 mg, scale 0.5 %,
    angles 2 mrad, 1 σ); the temperature terms by 20 % of their size; ``valid_c`` by
    up to 0.3 °C at each end.
    """
    constant_sd = np.repeat([10e-3, 5e-3, 2e-3, 2e-3], 3)
    for _ in range(n):
        coeffs = model.coeffs.copy()
        coeffs[:, 0] += rng.normal(0.0, constant_sd)
        coeffs[:, 1:] *= 1.0 + rng.normal(0.0, 0.2, coeffs[:, 1:].shape)
        lo, hi = model.valid_c
        valid_c = (lo + rng.uniform(-0.3, 0.3), hi + rng.uniform(-0.3, 0.3))
        yield dataclasses.replace(model, coeffs=coeffs, valid_c=valid_c)


def seed_calibrations(
    database_url: str, n_calibrations: int, n_sensors: int, seed: int
) -> dict[str, float]:
    """Store the sensors and ``n_calibrations`` real-format calibrations; timings (s)."""
    import psycopg

    from service.engine.calibrate import model_document

    rng = np.random.default_rng(seed)
    t_fit = time.perf_counter()
    model, report, rmse_ug = real_model()
    fit_s = time.perf_counter() - t_fit

    # Calibrations arrive over a year, sensors interleaved: ids grow with created_at.
    now = dt.datetime.now(dt.UTC)
    sensor_of = np.arange(n_calibrations) % n_sensors
    age_days = np.sort(rng.uniform(0.0, HISTORY_DAYS, n_calibrations))[::-1]
    report_json = json.dumps(report, allow_nan=False)
    t_copy = time.perf_counter()
    columns = ("sensor", "created_at", "valid_lo_c", "valid_hi_c", "rmse_ug", "model_version",
               "model", "report", "provenance")
    with psycopg.connect(libpq_conninfo(database_url)) as conn, conn.cursor() as cur:
        with cur.copy("COPY sensors (serial, model, created_at) FROM STDIN") as copy:
            for s in range(n_sensors):
                copy.write_row((SERIAL_FORMAT.format(s), "ADXL355", now - dt.timedelta(days=400)))
        with cur.copy(f"COPY calibrations ({', '.join(columns)}) FROM STDIN") as copy:
            for i, variant in enumerate(model_variants(model, n_calibrations, rng)):
                serial = SERIAL_FORMAT.format(int(sensor_of[i]))
                provenance = {"recording": f"{serial}-{i:05d}.csv", "bench": True}
                doc = model_document(variant)
                doc.setdefault("provenance", {}).update(provenance)
                copy.write_row((
                    serial,
                    now - dt.timedelta(days=float(age_days[i])),
                    float(variant.valid_c[0]),
                    float(variant.valid_c[1]),
                    rmse_ug * float(rng.uniform(0.8, 1.25)),
                    str(variant.model_version),
                    json.dumps(doc, allow_nan=False),
                    report_json,
                    json.dumps(provenance),
                ))
        conn.commit()
        conn.autocommit = True
        conn.execute("VACUUM ANALYZE calibrations")
        conn.execute("VACUUM ANALYZE sensors")
    return {"fit_s": fit_s, "store_s": time.perf_counter() - t_copy}


def query_plan(database_url: str) -> tuple[dict[str, int], tuple[float, float], int]:
    """Each sensor's newest calibration id, the range valid for every one, stored bytes."""
    import psycopg

    with psycopg.connect(libpq_conninfo(database_url)) as conn:
        newest = conn.execute(
            "SELECT DISTINCT ON (sensor) sensor, id, valid_lo_c, valid_hi_c FROM calibrations "
            "ORDER BY sensor, created_at DESC, id DESC"
        ).fetchall()
        size_bytes = conn.execute(
            "SELECT pg_total_relation_size('calibrations')"
        ).fetchone()[0]  # type: ignore[index]
    latest_id = {row[0]: int(row[1]) for row in newest}
    common_c = (max(float(r[2]) for r in newest), min(float(r[3]) for r in newest))
    return latest_id, common_c, int(size_bytes)


def database_sessions(database_url: str) -> int:
    """Sessions (backend connections) ever opened to the database (PostgreSQL >= 14 stats).

    Read over a connection to ``postgres`` so the reading itself is not counted.
    """
    import psycopg
    from sqlalchemy import make_url

    name = make_url(database_url).database
    with psycopg.connect(libpq_conninfo(database_url, "postgres")) as conn:
        row = conn.execute(
            "SELECT sessions FROM pg_stat_database WHERE datname = %s", (name,)
        ).fetchone()
    return int(row[0]) if row and row[0] is not None else -1


def make_viewer_token(database_url: str) -> str:
    from service.api.auth import create_token
    from service.db.session import make_session_factory, session_scope

    factory = make_session_factory(database_url)
    try:
        with session_scope(factory) as session:
            return create_token(session, "viewer", "bench_query_latency")
    finally:
        factory.kw["bind"].dispose()


# --- the service ----------------------------------------------------------------
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def soakcal_executable() -> str:
    """``soakcal`` next to the running interpreter (the venv's), else on PATH."""
    beside = Path(sys.executable).with_name("soakcal")
    if beside.exists():
        return str(beside)
    found = shutil.which("soakcal")
    if found is None:
        raise SystemExit("soakcal is not installed (make venv)")
    return found


def start_service(database_url: str, port: int, workdir: Path) -> subprocess.Popen[bytes]:
    """``soakcal serve --port PORT`` over ``database_url``; output goes to workdir/serve.log."""
    env = dict(os.environ, SOAKCAL_DATABASE_URL=database_url, SOAKCAL_DATA_DIR=str(workdir))
    log = (workdir / "serve.log").open("wb")
    return subprocess.Popen(
        [soakcal_executable(), "serve", "--host", "127.0.0.1", "--port", str(port)],
        env=env, stdout=log, stderr=subprocess.STDOUT, cwd=workdir,
    )


def wait_healthy(base_url: str, proc: subprocess.Popen[bytes], workdir: Path,
                 timeout_s: float = 120.0) -> None:
    import httpx

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            tail = (workdir / "serve.log").read_text(errors="replace")[-3000:]
            raise SystemExit(f"soakcal serve exited with {proc.returncode}:\n{tail}")
        try:
            if httpx.get(base_url + HEALTH_PATH, timeout=2.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise SystemExit(f"soakcal serve did not become healthy within {timeout_s:.0f} s")


def stop_service(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def process_cpu_s(pid: int) -> float:
    """User + system CPU time (s) of a process, all threads, from /proc (Linux)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# --- the load -------------------------------------------------------------------
@dataclasses.dataclass
class Sample:
    """One request: when it was due, when it was sent, how it ended."""

    due_s: float
    wait_ms: float  # due -> sent: scheduler lateness + waiting for a free client worker
    latency_ms: float
    status: int  # HTTP status; 0 = transport error or timeout
    wrong: bool = False
    error: str = ""


class RawHttpConnection:
    """One keep-alive HTTP/1.1 connection over asyncio streams: just enough for GET + JSON.

    ~5x less client CPU per request than httpx, which matters when the client shares
    two cores with the service and the database. Needs ``Content-Length`` responses
    (uvicorn sends them for JSON); reconnects after an error or ``Connection: close``.
    """

    def __init__(self, host: str, port: int, token: str, timeout_s: float) -> None:
        self.host, self.port, self.timeout_s = host, port, timeout_s
        self._head = (f"Host: {host}:{port}\r\nAuthorization: Bearer {token}\r\n"
                      "Accept: application/json\r\n\r\n").encode("ascii")
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None

    async def get(self, path: str) -> tuple[int, bytes]:
        """``(status, body)`` of ``GET path``; raises OSError/TimeoutError/ValueError."""
        try:
            async with asyncio.timeout(self.timeout_s):
                return await self._get(path)
        except BaseException:
            await self.close()
            raise

    async def _get(self, path: str) -> tuple[int, bytes]:
        if self._writer is None:
            self._reader, self._writer = await asyncio.open_connection(self.host, self.port)
        assert self._reader is not None
        self._writer.write(b"GET " + path.encode("ascii") + b" HTTP/1.1\r\n" + self._head)
        head = (await self._reader.readuntil(b"\r\n\r\n")).decode("latin-1").lower()
        status = int(head[9:12])
        length, keep_alive = None, True
        for line in head.split("\r\n")[1:]:
            name, _, value = line.partition(":")
            if name == "content-length":
                length = int(value)
            elif name == "connection" and "close" in value:
                keep_alive = False
        if length is None:
            raise ValueError("response without Content-Length")
        body = await self._reader.readexactly(length)
        if not keep_alive:
            await self.close()
        return status, body

    async def close(self) -> None:
        writer, self._reader, self._writer = self._writer, None, None
        if writer is not None:
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()


class HttpxConnection:
    """The same interface over an ``httpx.AsyncClient`` limited to one connection."""

    def __init__(self, base_url: str, token: str, timeout_s: float) -> None:
        import httpx

        self._client = httpx.AsyncClient(
            base_url=base_url, headers={"Authorization": f"Bearer {token}"}, timeout=timeout_s,
            limits=httpx.Limits(max_connections=1, max_keepalive_connections=1),
        )

    async def get(self, path: str) -> tuple[int, bytes]:
        response = await self._client.get(path)
        return response.status_code, response.content

    async def close(self) -> None:
        await self._client.aclose()


async def run_load(
    base_url: str, token: str, latest_id: dict[str, int], range_c: tuple[float, float],
    rate: float, total_s: float, connections: int, seed: int, timeout_s: float,
    client: str = "raw",
) -> tuple[list[Sample], float, list[tuple[float, float]]]:
    """Open-loop load: the samples, request 0's due (loop) time, the scheduler's lateness.

    A scheduler coroutine releases request *i* at its due time into a queue;
    ``connections`` workers, each with its own keep-alive connection, take requests
    from the queue. When every worker is busy, requests wait in the queue -- and that
    wait is part of their latency, which runs from the due time. (Not one shared httpx
    pool: it does work per waiting request on every state change, so a backlog in it
    makes the *client* CPU-bound.)

    The lateness list holds ``(due_s, release_lag_ms)``: how late the scheduler put each
    request into the queue. It stays near zero unless the client itself is starved of CPU.
    """
    rng = np.random.default_rng(seed + 1)
    serials = sorted(latest_id)
    n = int(round(rate * total_s))
    pick = rng.integers(0, len(serials), n)
    temps_c = np.round(rng.uniform(range_c[0], range_c[1], n), 2)
    samples: list[Sample] = []
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue[tuple[float, str, float] | None] = asyncio.Queue()
    host_port = base_url.split("://", 1)[1]
    host, port = host_port.rsplit(":", 1)

    def connect() -> RawHttpConnection | HttpxConnection:
        if client == "httpx":
            return HttpxConnection(base_url, token, timeout_s)
        return RawHttpConnection(host, int(port), token, timeout_s)

    async def one(conn: RawHttpConnection | HttpxConnection, due: float, serial: str,
                  temperature_c: float) -> Sample:
        wait_ms = (loop.time() - due) * 1e3
        path = COEFFICIENTS_PATH.format(serial=serial) + f"?temperature_c={temperature_c:.2f}"
        try:
            status, body = await conn.get(path)
            latency_ms = (loop.time() - due) * 1e3
        except Exception as exc:  # transport errors and timeouts are results here
            return Sample(due, wait_ms, (loop.time() - due) * 1e3, 0, error=type(exc).__name__)
        wrong = status == 200 and json.loads(body).get("calibration_id") != latest_id[serial]
        return Sample(due, wait_ms, latency_ms, status, wrong)

    async def worker(k: int, warmed: asyncio.Event, ready: asyncio.Event) -> None:
        conn = connect()
        try:
            # Open the connection and warm the service (imports, caches) before t0.
            for j in range(3):
                await one(conn, loop.time(), serials[(7 * k + j) % len(serials)], 20.0)
            warmed.set()
            await ready.wait()
            while (item := await queue.get()) is not None:
                samples.append(await one(conn, *item))
        finally:
            await conn.close()

    ready = asyncio.Event()
    warmed = [asyncio.Event() for _ in range(connections)]
    workers = [asyncio.create_task(worker(k, warmed[k], ready)) for k in range(connections)]
    await asyncio.wait_for(asyncio.gather(*(w.wait() for w in warmed)), timeout=120.0)
    t0 = loop.time() + 0.2
    ready.set()
    release_lag: list[tuple[float, float]] = []
    for i in range(n):
        due = t0 + i / rate
        delay = due - loop.time()
        if delay > 0:
            await asyncio.sleep(delay)
        release_lag.append((due, (loop.time() - due) * 1e3))
        queue.put_nowait((due, serials[pick[i]], float(temps_c[i])))
    for _ in workers:
        queue.put_nowait(None)
    await asyncio.gather(*workers)
    return samples, t0, release_lag


def percentile_ms(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else math.nan


def summarise(samples: list[Sample], t0: float, release_lag: list[tuple[float, float]],
              warmup_s: float, rate: float, duration_s: float) -> dict[str, Any]:
    """Latency percentiles and counts over the requests due after the warm-up."""
    window_start = t0 + warmup_s
    measured = [s for s in samples if s.due_s >= window_start - 1e-9]
    latency = np.array([s.latency_ms for s in measured])
    wait = np.array([s.wait_ms for s in measured])
    lag = np.array([ms for due, ms in release_lag if due >= window_start - 1e-9])
    last_end_s = max((s.due_s + s.latency_ms / 1e3 for s in measured), default=window_start)
    span_s = max(last_end_s - window_start, 1e-9)
    errors: dict[str, int] = {}
    for s in measured:
        if s.status != 200:
            key = s.error or str(s.status)
            errors[key] = errors.get(key, 0) + 1
    return {
        "requests": len(measured),
        "offered_rate_per_s": rate,
        "duration_s": duration_s,
        "achieved_rate_per_s": len(measured) / span_s,
        "latency_ms": {
            "p50": percentile_ms(latency, 50),
            "p90": percentile_ms(latency, 90),
            "p99": percentile_ms(latency, 99),
            "p99_9": percentile_ms(latency, 99.9),
            "max": float(latency.max()) if latency.size else math.nan,
            "mean": float(latency.mean()) if latency.size else math.nan,
        },
        "non_200": sum(1 for s in measured if s.status != 200),
        "errors_by_kind": errors,
        "wrong_calibration_id": sum(1 for s in measured if s.wrong),
        # Scheduler lateness: the client's own health (near 0 unless it is starved of CPU).
        "client_release_lag_ms": {
            "p99": percentile_ms(lag, 99),
            "max": float(lag.max()) if lag.size else math.nan,
        },
        # Due -> sent: lateness plus waiting for a free worker (all busy = server backlog).
        "client_wait_ms": {
            "p50": percentile_ms(wait, 50),
            "p99": percentile_ms(wait, 99),
            "max": float(wait.max()) if wait.size else math.nan,
        },
    }


# --- main -----------------------------------------------------------------------
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--database-url", default=DEFAULT_DATABASE_URL,
                    help="PostgreSQL URL of the benchmark database; its name must contain "
                    "'bench' because it is DROPPED and recreated (default %(default)s)")
    ap.add_argument("--calibrations", type=int, default=10_000, help="stored calibrations")
    ap.add_argument("--sensors", type=int, default=500, help="distinct sensors")
    ap.add_argument("--rate", type=float, default=200.0, help="requests per second (open loop)")
    ap.add_argument("--duration-s", type=float, default=60.0, help="measured seconds")
    ap.add_argument("--warmup-s", type=float, default=5.0,
                    help="seconds at the same rate before the measured window (not counted)")
    ap.add_argument("--connections", type=int, default=32,
                    help="client workers, one keep-alive connection each: the most requests "
                    "in flight at once; more wait, counted, in the client queue "
                    "(default %(default)s)")
    ap.add_argument("--timeout-s", type=float, default=10.0, help="per-request timeout")
    ap.add_argument("--client", choices=("raw", "httpx"), default="raw",
                    help="raw: a minimal HTTP/1.1 client on asyncio streams (least client CPU); "
                    "httpx: httpx.AsyncClient, one per worker (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", metavar="PATH", help="also write the results as JSON here")
    args = ap.parse_args(argv)
    if not 0 < args.sensors <= args.calibrations:
        ap.error("need 0 < --sensors <= --calibrations")
    if args.rate <= 0 or args.duration_s <= 0 or args.warmup_s < 0 or args.connections < 1:
        ap.error("--rate, --duration-s and --connections must be positive, --warmup-s >= 0")
    return args


def _exit_on_sigterm(signum: int, _frame: Any) -> None:
    raise SystemExit(128 + signum)  # so ``finally`` stops the service subprocess


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    print(f"database: recreating {args.database_url.rsplit('/', 1)[-1]} and migrating ...",
          flush=True)
    recreate_database(args.database_url)
    from service.db.session import upgrade_database

    upgrade_database(args.database_url)
    timings = seed_calibrations(args.database_url, args.calibrations, args.sensors, args.seed)
    latest_id, range_c, table_bytes = query_plan(args.database_url)
    print(f"stored {args.calibrations} calibrations of {len(latest_id)} sensors "
          f"(one real fit {timings['fit_s']:.1f} s, COPY + ANALYZE {timings['store_s']:.1f} s; "
          f"calibrations table {table_bytes / 1e6:.0f} MB); querying T in "
          f"[{range_c[0]:.2f}, {range_c[1]:.2f}] °C", flush=True)
    token = make_viewer_token(args.database_url)

    with tempfile.TemporaryDirectory(prefix="bench-query-") as tmp:
        workdir = Path(tmp)
        port = free_port()
        base_url = f"http://127.0.0.1:{port}"
        proc = start_service(args.database_url, port, workdir)
        try:
            wait_healthy(base_url, proc, workdir)
            print(f"soakcal serve pid {proc.pid} on port {port}; open-loop load "
                  f"{args.rate:g}/s for {args.warmup_s:g} s warm-up + {args.duration_s:g} s",
                  flush=True)
            sessions0 = database_sessions(args.database_url)
            load_before = os.getloadavg()  # others' load: the service is idle, seeding done
            cpu0_s = process_cpu_s(proc.pid)
            client_cpu0_s = time.process_time()
            wall0_s = time.monotonic()
            samples, t0, release_lag = asyncio.run(run_load(
                base_url, token, latest_id, range_c, args.rate,
                args.warmup_s + args.duration_s, args.connections, args.seed, args.timeout_s,
                args.client,
            ))
            wall_s = time.monotonic() - wall0_s
            service_cpu_s = process_cpu_s(proc.pid) - cpu0_s
            client_cpu_s = time.process_time() - client_cpu0_s
            time.sleep(1.0)  # backends report their stats at most once a second
            sessions_opened = database_sessions(args.database_url) - sessions0
            if proc.poll() is not None:
                print(f"warning: soakcal serve exited with {proc.returncode} during the run")
        finally:
            stop_service(proc)

    result = summarise(samples, t0, release_lag, args.warmup_s, args.rate, args.duration_s)
    n_all = max(len(samples), 1)
    result.update({
        "finished_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "command": " ".join([".venv/bin/python", "benchmarks/bench_query_latency.py",
                             *(sys.argv[1:] if argv is None else argv)]),
        "calibrations": args.calibrations,
        "sensors": len(latest_id),
        "connections": args.connections,
        "client": args.client,
        "calibrations_table_mb": table_bytes / 1e6,
        "service_cpu_ms_per_request": service_cpu_s * 1e3 / n_all,
        "client_cpu_ms_per_request": client_cpu_s * 1e3 / n_all,
        "service_cpu_utilisation": service_cpu_s / wall_s,
        "database_connections_opened": sessions_opened,
        "cpu_count": os.cpu_count(),
        "load_average_before": list(load_before),
        "load_average_after": list(os.getloadavg()),
    })
    print_report(result)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return 0 if result["non_200"] == 0 and result["wrong_calibration_id"] == 0 else 1


def print_report(r: dict[str, Any]) -> None:
    lat = r["latency_ms"]
    lag = r["client_release_lag_ms"]
    wait = r["client_wait_ms"]
    print()
    print(f"GET {COEFFICIENTS_PATH}?temperature_c=T  ({r['calibrations']} calibrations, "
          f"{r['sensors']} sensors, PostgreSQL)")
    print(f"  offered {r['offered_rate_per_s']:g}/s open loop for {r['duration_s']:g} s: "
          f"{r['requests']} requests, achieved {r['achieved_rate_per_s']:.1f}/s")
    print(f"  latency ms (from due time): p50 {lat['p50']:.2f}  p90 {lat['p90']:.2f}  "
          f"p99 {lat['p99']:.2f}  p99.9 {lat['p99_9']:.2f}  max {lat['max']:.2f}  "
          f"(mean {lat['mean']:.2f})")
    print(f"  non-200: {r['non_200']} {r['errors_by_kind'] or ''}  "
          f"wrong calibration_id: {r['wrong_calibration_id']}")
    print(f"  service CPU {r['service_cpu_ms_per_request']:.2f} ms/request "
          f"({100 * r['service_cpu_utilisation']:.0f} % of one core); client CPU "
          f"{r['client_cpu_ms_per_request']:.2f} ms/request; new database connections "
          f"{r['database_connections_opened']}")
    print(f"  client: scheduler lateness p99 {lag['p99']:.2f} ms, max {lag['max']:.2f} ms; "
          f"wait for a free worker p50 {wait['p50']:.2f}, p99 {wait['p99']:.2f} ms")
    before = ", ".join(f"{v:.2f}" for v in r["load_average_before"])
    after = ", ".join(f"{v:.2f}" for v in r["load_average_after"])
    print(f"  machine: {r['cpu_count']} CPUs, load average (1, 5, 15 min) before "
          f"{before}, after {after}")


if __name__ == "__main__":
    raise SystemExit(main())
