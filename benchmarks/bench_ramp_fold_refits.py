"""The ramp campaign's fitting phase: Levenberg–Marquardt solves, evaluations and CPU.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ramp_fold_refits.py \
        [--sim-speed 3000 40000 80000]

The browser tests' ramp campaign (``tests/web/conftest.py``: sim rig, 20 → 60 °C and back
at 0.5 °C/min) run in this process by the service's engine at each ``--sim-speed`` (× wall).
A faster clock stands for a loaded machine: the engine lags the rig's clock and takes fewer
readings per simulated minute. Every ``scipy.optimize.least_squares`` call of the fitting
phase is counted by its caller: the continuous fit's all-row solves (one per degree and the
final) and the fold refits' LM fallback (``_refit_without`` where its Gauss–Newton step does
not lower χ² or the normal equations are not positive definite), with their function
evaluations (``nfev``) and the engine thread's CPU inside them; and the whole
``fit_continuous`` call's thread CPU. The readings depend on the machine's timing: the rows
and the counts vary from run to run.
"""

from __future__ import annotations

import argparse
import collections
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import scipy.optimize

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "tests" / "web"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

_LEAST_SQUARES = scipy.optimize.least_squares
SOLVES: collections.Counter[str] = collections.Counter()
NFEV: collections.Counter[str] = collections.Counter()
CPU_S: collections.Counter[str] = collections.Counter()
FALLBACKS: list[str] = []  # each fold-refit LM fallback: its nfev, and "max" when it ran out


def _counted_least_squares(*args: Any, **kw: Any) -> Any:
    import traceback

    callers = [f.name for f in traceback.extract_stack(limit=4)[:-1]]
    key = "fold refit (LM fallback)" if "_refit_without" in callers else "all-row solve"
    t0 = time.thread_time()
    sol = _LEAST_SQUARES(*args, **kw)
    SOLVES[key] += 1
    NFEV[key] += int(sol.nfev)
    CPU_S[key] += time.thread_time() - t0
    if key.startswith("fold"):
        FALLBACKS.append(f"{sol.nfev}{' (max_nfev)' if sol.status == 0 else ''}")
    return sol


scipy.optimize.least_squares = _counted_least_squares  # before calibration imports it


def run_campaign(sim_speed: float) -> tuple[str, int]:
    """One ramp campaign through the service at ``sim_speed``: (its end state, fit rows)."""
    import uvicorn
    from web_helpers import LiveService

    from calibration import continuous
    from service.api.app import create_app
    from service.api.auth import create_token
    from service.config import Settings
    from service.db.session import session_scope

    fit_continuous = continuous.fit_continuous
    rows: list[int] = []

    def counted_fit(recording: Any, seg: Any, **kw: Any) -> Any:
        t0 = time.thread_time()
        try:
            return fit_continuous(recording, seg, **kw)
        finally:
            CPU_S["fit_continuous (whole)"] += time.thread_time() - t0
            rows.append(len(recording))

    continuous.fit_continuous = counted_fit  # type: ignore[assignment]
    with tempfile.TemporaryDirectory() as tmp:
        app = create_app(Settings(database_url=f"sqlite:///{tmp}/bench.db", run_engine=True,
                                  run_scheduler=False, sim_speed=sim_speed,
                                  events_poll_s=0.1))
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port,
                                               log_level="warning"))
        thread = threading.Thread(target=server.run, daemon=True)
        thread.start()
        while not server.started:
            time.sleep(0.02)
        with session_scope(app.state.session_factory) as session:
            tokens = {"operator": create_token(session, "operator", "bench")}
        svc = LiveService(url=f"http://127.0.0.1:{port}", tokens=tokens)
        created = svc.start_campaign("SN-RAMP", method="ramp", setpoints_c=[20, 60],
                                     ramp_c_per_min=0.5)
        state = svc.wait_campaign(created["id"], "completed", "failed", "aborted",
                                  cpu_s=600)["state"]
        server.should_exit = True
        thread.join(timeout=20)
    continuous.fit_continuous = fit_continuous  # type: ignore[assignment]
    return state, rows[0] if rows else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sim-speed", type=float, nargs="+", default=[3000.0, 40000.0, 80000.0])
    args = ap.parse_args()
    print("| sim speed | state | rows | all-row solves (nfev) | fold-refit LM fallbacks "
          "(nfev) | each fallback's nfev | CPU in LM, s | fit_continuous CPU, s |")
    print("|---|---|---|---|---|---|---|---|")
    for speed in args.sim_speed:
        SOLVES.clear()
        NFEV.clear()
        CPU_S.clear()
        FALLBACKS.clear()
        state, rows = run_campaign(speed)
        a, f = "all-row solve", "fold refit (LM fallback)"
        print(f"| {speed:g}× | {state} | {rows} | {SOLVES[a]} ({NFEV[a]}) | {SOLVES[f]} "
              f"({NFEV[f]}) | {', '.join(FALLBACKS) or '–'} | {CPU_S[a] + CPU_S[f]:.2f} | "
              f"{CPU_S['fit_continuous (whole)']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
