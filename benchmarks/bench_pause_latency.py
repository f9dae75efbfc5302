"""How long a pause request waits for the engine's next safe point, on the live service.

Runs the service as the browser tests do (sim rig at 3000×, SQLite), starts the
campaign the live-pause browser test started before it was made race-free
(setpoints 20..60, soak_min 60, table1, 20 samples), and records the wall time of
every checkpoint (``CampaignRunner._checkpoint``: where a pause applies) with the
campaign's phase. Prints the campaign's wall duration, the longest gaps between
checkpoints (what a pause can wait) and the measured request → "paused" latency of
pauses requested at several moments of further campaigns. A pause asked after the last
checkpoint (the last position's, then the fit) is not applied: the campaign completes.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/bench_pause_latency.py
"""

from __future__ import annotations

import socket
import sys
import tempfile
import threading
import time
import urllib.error
from pathlib import Path

import uvicorn

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "web"))
from web_helpers import LiveService  # noqa: E402

from service.engine import runner as runner_mod  # noqa: E402

SPEC = {"setpoints_c": [20, 30, 40, 50, 60], "soak_min": 60}
marks: list[tuple[float, str]] = []
_orig = runner_mod.CampaignRunner._checkpoint


async def _traced(self):  # type: ignore[no-untyped-def]
    marks.append((time.monotonic(), str(self._progress.get("phase"))))
    await _orig(self)


runner_mod.CampaignRunner._checkpoint = _traced  # type: ignore[method-assign]


def serve(db: Path) -> LiveService:
    from service.api.app import create_app
    from service.api.auth import create_token
    from service.config import Settings
    from service.db.session import session_scope

    app = create_app(Settings(database_url=f"sqlite:///{db}", run_engine=True,
                              run_scheduler=False, sim_speed=3000.0, events_poll_s=0.1))
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    threading.Thread(target=server.run, daemon=True).start()
    while not server.started:
        time.sleep(0.02)
    with session_scope(app.state.session_factory) as session:
        token = create_token(session, "operator", "bench")
    return LiveService(url=f"http://127.0.0.1:{port}", tokens={"operator": token})


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        svc = serve(Path(tmp) / "bench.db")
        t0 = time.monotonic()
        c = svc.start_campaign("SN-BENCH", **SPEC)
        svc.wait_campaign(c["id"], "completed", "failed", "aborted", timeout_s=300)
        wall_s = time.monotonic() - t0
        gaps = sorted(((b[0] - a[0], a[1], b[1]) for a, b in zip(marks, marks[1:], strict=False)),
                      reverse=True)
        print(f"campaign wall time {wall_s:.1f} s, {len(marks)} checkpoints; "
              f"last checkpoint → completed {t0 + wall_s - marks[-1][0]:.2f} s")
        for gap_s, before, after in gaps[:5]:
            print(f"  gap {gap_s:.3f} s between checkpoints ({before} → {after})")
        for after_s in (1.0, 3.0, 6.0, 9.0):
            c = svc.start_campaign("SN-BENCH", **SPEC)
            svc.wait_campaign(c["id"], "running")
            time.sleep(after_s)
            asked = time.monotonic()
            try:
                svc.call("POST", f"/api/v1/campaigns/{c['id']}/pause")
            except urllib.error.HTTPError as exc:  # the race the browser test had
                state = svc.call("GET", f"/api/v1/campaigns/{c['id']}")["state"]
                print(f"pause asked {after_s:.0f} s after start: HTTP {exc.code}, the "
                      f"campaign had already {state}")
                continue
            got = svc.wait_campaign(c["id"], "paused", "completed", "failed", timeout_s=120)
            print(f"pause asked {after_s:.0f} s after start: {got['state']} after "
                  f"{time.monotonic() - asked:.2f} s")
            if got["state"] == "paused":
                svc.abort(c["id"])


if __name__ == "__main__":
    main()
