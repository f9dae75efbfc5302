"""The door under oversized bodies: status codes, server memory and time to refuse.

Starts ``soakcal serve`` (its own throw-away SOAKCAL_HOME, SQLite) and sends
``--n`` POST /api/v1/campaigns of ``--mb`` MB each, three ways:

* unauthenticated, with Content-Length  (expected 401, body never read);
* authenticated, with Content-Length    (expected 413, body never read);
* authenticated, streamed (chunked)     (expected 413 once the limit is passed).

Reports the server's resident memory (VmRSS) before and after, and the
median time to the refusal. The audit before this work saw 4 × 50 MB
unauthenticated POSTs answered 422 and the server grow 164 → 683 MB.

    .venv/bin/python benchmarks/bench_door.py --n 4 --mb 50
"""

from __future__ import annotations

import argparse
import os
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


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _chunks(total: int, size: int = 1 << 20) -> Iterator[bytes]:
    sent = 0
    while sent < total:
        n = min(size, total - sent)
        sent += n
        yield b" " * n


def _post(client: httpx.Client, body: bytes | Iterator[bytes], headers: dict[str, str]
          ) -> tuple[str, float]:
    t0 = time.perf_counter()
    try:
        status = str(client.post("/api/v1/campaigns", content=body, headers=headers).status_code)
    except httpx.HTTPError as exc:  # the server may close while we still send
        status = f"closed ({type(exc).__name__})"
    return status, time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=4, help="requests per kind")
    parser.add_argument("--mb", type=float, default=50.0, help="body size, MB")
    args = parser.parse_args()
    size = int(args.mb * 1_000_000)
    home = tempfile.mkdtemp(prefix="soakcal-bench-door-")
    env = {**os.environ, "SOAKCAL_HOME": home}
    env.pop("SOAKCAL_DATABASE_URL", None)
    token = subprocess.run([SOAKCAL, "token", "create", "--role", "operator"], env=env,
                           check=True, capture_output=True, text=True).stdout.split()[-1]
    port = _free_port()
    server = subprocess.Popen([SOAKCAL, "serve", "--port", str(port)], env=env, cwd=home,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        url = f"http://127.0.0.1:{port}"
        with httpx.Client(base_url=url, timeout=120.0) as client:
            for _ in range(200):
                try:
                    if client.get("/api/v1/health").status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                time.sleep(0.1)
            rss0 = _rss_mb(server.pid)
            big = b"x" * size
            json_type = {"Content-Type": "application/json"}
            auth = {**json_type, "Authorization": f"Bearer {token}"}
            kinds = {
                "unauthenticated, Content-Length": lambda: _post(client, big, json_type),
                "authenticated, Content-Length": lambda: _post(client, big, auth),
                "authenticated, streamed": lambda: _post(client, _chunks(size), auth),
            }
            print(f"{args.n} × {args.mb:g} MB POST /api/v1/campaigns per kind; "
                  f"server RSS at start {rss0:.0f} MB")
            for name, call in kinds.items():
                results = [call() for _ in range(args.n)]
                statuses = sorted({s for s, _ in results})
                median_ms = statistics.median(t for _, t in results) * 1000.0
                print(f"  {name:34s} status {', '.join(statuses):12s} "
                      f"median {median_ms:7.1f} ms  server RSS {_rss_mb(server.pid):.0f} MB")
            ok = client.post("/api/v1/campaigns", json={"rig": "sim", "sensor": "SN-B1"},
                             headers=auth)
            print(f"  a normal campaign afterwards: {ok.status_code}, predicted "
                  f"{ok.json().get('predicted_duration_s', 0) / 3600:.1f} h of rig time")
            print(f"server RSS at the end {_rss_mb(server.pid):.0f} MB "
                  f"(grew {_rss_mb(server.pid) - rss0:+.0f} MB)")
    finally:
        server.terminate()
        server.wait(timeout=30)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
