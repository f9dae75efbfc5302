"""Dashboard page weight and time to first progress event on the ``sim`` rig.

    .venv/bin/python benchmarks/bench_dashboard.py [--runs 5] [--sim-speed 600] [--json PATH]

What it does:

1. Starts ``soakcal serve`` (the real CLI: migrations, campaign engine, scheduler,
   uvicorn) as a subprocess on a free port with a temporary ``SOAKCAL_DATA_DIR``
   (embedded SQLite), waits for ``GET /api/v1/health`` and creates an operator token
   with ``soakcal token create``.
2. Page weight: fetches ``/`` and every asset the browser loads for it (``<script src>``,
   ``<link href>``, ``<img src>``; for ``/docs`` and ``/redoc`` also the OpenAPI document
   their scripts fetch); bytes as sent (the service does not compress responses). The
   dashboard's later API calls (JSON, figures) are data, not page weight.
3. Time to first progress event, ``--runs`` times: ``POST /api/v1/campaigns`` (a short
   campaign: setpoints 20, 30 °C, 5 min soak, table1, 20 samples per position), then at
   once ``GET /api/v1/campaigns/{id}/events`` (the SSE stream the dashboard's
   ``EventSource`` opens). Times from just before the POST to: the first ``progress``
   event (the stream's snapshot), the first event with state ``running`` (the engine
   took the campaign), and the first event whose progress differs from that one (the
   run moved). The campaign is then aborted and awaited before the next run.
4. Prints a table and the median of each figure; ``--json`` also writes them.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent
SOAKCAL = str(Path(sys.executable).parent / "soakcal")
CAMPAIGN = {
    "rig": "sim",
    "sensor": "SN-BENCH",
    "setpoints_c": [20.0, 30.0],
    "soak_min": 5.0,
    "positions": "table1",
    "samples_per_position": 20,
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--sim-speed", type=float, default=600.0)
    parser.add_argument("--json", metavar="PATH")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-dashboard-") as tmp, _service(
        Path(tmp), args.sim_speed
    ) as (url, token):
        headers = {"Authorization": f"Bearer {token}"}
        with httpx.Client(base_url=url, headers=headers, timeout=60.0) as client:
            weights = {page: page_weight(client, page) for page in ("/", "/docs", "/redoc")}
            runs = [first_progress(client) for _ in range(args.runs)]
    report(weights, runs, args)
    return 0


@contextlib.contextmanager
def _service(tmp: Path, sim_speed: float) -> Iterator[tuple[str, str]]:
    env = {**os.environ, "SOAKCAL_DATA_DIR": str(tmp / "data")}
    env.pop("SOAKCAL_DATABASE_URL", None)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    token = subprocess.run(
        [SOAKCAL, "token", "create", "--role", "operator", "--name", "bench"],
        env=env, check=True, capture_output=True, text=True,
    ).stdout.strip().splitlines()[-1]
    log = open(tmp / "serve.log", "w")  # noqa: SIM115 (closed below)
    proc = subprocess.Popen(
        [SOAKCAL, "serve", "--port", str(port), "--sim-speed", str(sim_speed)],
        env=env, stdout=log, stderr=subprocess.STDOUT,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(url + "/api/v1/health", timeout=1).status_code == 200:
                    break
            time.sleep(0.1)
        else:
            raise SystemExit(f"soakcal serve did not answer within 30 s; see {tmp}/serve.log")
        yield url, token
    finally:
        proc.terminate()
        proc.wait(timeout=30)
        log.close()


def page_weight(client: httpx.Client, page: str) -> dict[str, int]:
    """Bytes of ``page`` and each same-origin asset it references."""
    html = client.get(page)
    html.raise_for_status()
    sizes = {page: len(html.content)}
    # what the browser loads: <script src>, <link href>, <img src>, and the OpenAPI
    # document Swagger UI (url: '...') and ReDoc (spec-url) fetch; not <a href> links
    found = re.findall(
        r'<(?:script|link|img)\b[^>]*?\b(?:src|href)="([^"]+)"'
        r"|spec-url=\"([^\"]+)\"|\burl: *'([^']+)'",
        html.text,
    )
    for groups in found:
        asset = next(g for g in groups if g)
        if asset.startswith("/") and not asset.startswith("//") and asset not in sizes:
            response = client.get(asset)
            response.raise_for_status()
            sizes[asset] = len(response.content)
    return sizes


def first_progress(client: httpx.Client) -> dict[str, float]:
    t0 = time.perf_counter()
    created = client.post("/api/v1/campaigns", json=CAMPAIGN)
    created.raise_for_status()
    campaign_id = created.json()["id"]
    times: dict[str, float] = {}
    running: str | None = None
    with client.stream("GET", f"/api/v1/campaigns/{campaign_id}/events", timeout=60) as stream:
        event = None
        for line in stream.iter_lines():
            if line.startswith("event:"):
                event = line[6:].strip()
            elif line.startswith("data:") and event == "progress":
                now_s = time.perf_counter() - t0
                view = json.loads(line[5:])
                times.setdefault("first_event_s", now_s)
                if view["state"] == "running" and running is None:
                    running = json.dumps(view["progress"])
                    times["running_s"] = now_s
                elif running is not None and json.dumps(view["progress"]) != running:
                    times["moved_s"] = now_s
                    break
            elif line.startswith("data:") and event == "end":
                break
    client.post(f"/api/v1/campaigns/{campaign_id}/abort")
    deadline = time.monotonic() + 60
    while client.get(f"/api/v1/campaigns/{campaign_id}").json()["state"] != "aborted":
        if time.monotonic() > deadline:
            raise SystemExit(f"campaign {campaign_id} did not abort within 60 s")
        time.sleep(0.1)
    return times


def report(weights: dict[str, dict[str, int]], runs: list[dict[str, float]], args) -> None:  # type: ignore[no-untyped-def]
    print("page weight (bytes as served, uncompressed):")
    for page, sizes in weights.items():
        print(f"  {page:<7} total {sum(sizes.values()):>9,d} B   " + ", ".join(
            f"{k} {v:,d}" for k, v in sizes.items()))
    print(f"time to first progress event on the sim rig ({len(runs)} runs, "
          f"sim speed {args.sim_speed:g}):")
    keys = ("first_event_s", "running_s", "moved_s")
    print("  run  " + "  ".join(f"{k:>14}" for k in keys))
    for i, r in enumerate(runs):
        print(f"  {i:>3}  " + "  ".join(f"{r.get(k, float('nan')):>14.3f}" for k in keys))
    medians = {k: statistics.median(r[k] for r in runs if k in r) for k in keys}
    print("  med  " + "  ".join(f"{medians[k]:>14.3f}" for k in keys))
    if args.json:
        Path(args.json).write_text(json.dumps(
            {"weights": weights, "runs": runs, "medians_s": medians,
             "sim_speed": args.sim_speed}, indent=2))


if __name__ == "__main__":
    sys.exit(main())
