"""The ramp campaign's fitting phase: Levenberg–Marquardt solves, evaluations and CPU.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ramp_fold_refits.py \
        [--sim-speed 3000 40000 80000] [--save-dir DIR]
    ... bench_ramp_fold_refits.py --sparse-ramp-every 15 25 40 [--hold-every 7]
        [--sensors 8] [--seed 0]
    ... bench_ramp_fold_refits.py --fit-csv DIR/*.csv

The browser tests' ramp campaign (``tests/web/conftest.py``: sim rig, 20 → 60 °C and back
at 0.5 °C/min) run in this process by the service's engine at each ``--sim-speed`` (× wall).
A faster clock stands for a loaded machine: the engine lags the rig's clock and takes fewer
readings per simulated minute. Every ``scipy.optimize.least_squares`` call of the fitting
phase is counted by its caller: the continuous fit's all-row solves (one per degree and the
final) and the fold refits' LM fallback (``_refit_without`` where its Gauss–Newton step does
not lower χ² or the normal equations are not positive definite), with their function
evaluations (``nfev``) and the engine thread's CPU inside them; and the whole
``fit_continuous`` call's thread CPU; the degree chosen, its held-out rms residual and the
fit's |g| RMSE after calibration (the report's ``rmse_after_mg``), and the degrees the
search did not judge (the model's notes). The readings depend on the machine's timing: the
rows and the counts vary from run to run.

``--sparse-ramp-every K …`` (instead of the campaigns, with a known truth): a sparse
recording like the loaded engine's (most rows at two held temperatures, a few while the die
moves), made from ``bench_ramp_fit.py``'s twin sensors (``--sensors``, 15 µg hysteresis,
20 µg per °C/min rate gain): the chamber −40 → 60 → 25 °C at 1 °C/min holding
``HOLD_MIN`` at −40 and 60 °C, the table sweeping the 24 positions of seed Table 1, the
0.1 °C / 0.11 °C channel; kept: every ``--hold-every``-th row whose die is within 0.5 °C of
a hold and every K-th of the others. Fitted by ``fit_continuous``, judged as that bench
judges (a fresh static run at −35, −5, 25, 45 °C; ratio = pooled RMS vector error / the
oracle's), with the same solve counts.

``--fit-csv FILE …``: the same counts and figures for recordings on disk (the campaigns'
fitted recordings that ``--save-dir`` wrote: the same rows before and after a change).
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
HOLD_MIN = 120.0  # --sparse-ramp-every: the chamber's hold at each turnaround, min
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


def _fit_summary(fit: Any) -> dict[str, Any]:
    """The chosen degree, its held-out rms (µg), the fit's |g| RMSE after (mg) and the
    notes on degrees the search did not judge."""
    scores = fit.model.provenance.get("degree_heldout_rms_ug", {})
    return {"degree": fit.model.degree, "heldout_ug": scores.get(str(fit.model.degree)),
            "scores": scores, "rmse_after_mg": fit.report.get("rmse_after_mg"),
            "not_judged": [n for n in fit.notes if "not judged" in n]}


def run_campaign(sim_speed: float, save: Path | None = None
                 ) -> tuple[str, int, dict[str, Any]]:
    """One ramp campaign through the service at ``sim_speed``: (its end state, fit rows,
    :func:`_fit_summary` of its fit); ``save``: write the fitted recording there (CSV)."""
    import uvicorn
    from web_helpers import LiveService

    from calibration import continuous
    from service.api.app import create_app
    from service.api.auth import create_token
    from service.config import Settings
    from service.db.session import session_scope

    fit_continuous = continuous.fit_continuous
    rows: list[int] = []
    summary: dict[str, Any] = {}

    def counted_fit(recording: Any, seg: Any, **kw: Any) -> Any:
        t0 = time.thread_time()
        try:
            if save is not None:
                from calibration.recording import write_recording

                write_recording(save, recording)
            fit = fit_continuous(recording, seg, **kw)
            summary.update(_fit_summary(fit))
            return fit
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
    return state, rows[0] if rows else 0, summary


def _fit_row(label: str, k: int, rec: Any, truth: Any = None, seed: int = 0
             ) -> tuple[float, float]:
    """Fit ``rec`` with the solves counted and print its table row; (model, oracle) held-out
    sums of squares against ``truth`` (``bench_ramp_fit.heldout_sse``), zeros without."""
    import numpy as np
    from bench_ramp_fit import heldout_sse

    from calibration.continuous import fit_continuous
    from calibration.plateaus import segment_recording

    SOLVES.clear()
    NFEV.clear()
    CPU_S.clear()
    FALLBACKS.clear()
    t0 = time.thread_time()
    try:
        fit = fit_continuous(rec, segment_recording(rec))
    except Exception as exc:  # noqa: BLE001 (a refusal is a result here)
        print(f"| {label} | {k} | {len(rec)} | refused: {exc} ||||||||", flush=True)
        return 0.0, 0.0
    cpu = time.thread_time() - t0
    m, o = heldout_sse(fit.model, truth, seed) if truth is not None else (0.0, 0.0)
    s = _fit_summary(fit)
    a, f = "all-row solve", "fold refit (LM fallback)"
    print(f"| {label} | {k} | {len(rec)} | {SOLVES[a]} ({NFEV[a]}) | {SOLVES[f]} ({NFEV[f]}) | "
          f"{', '.join(FALLBACKS) or '–'} | {cpu:.2f} | {s['degree']} | {s['heldout_ug']} | "
          f"{s['rmse_after_mg']} | {f'{np.sqrt(m / o):.3f}' if o else '–'} | "
          f"{'; '.join(s['not_judged']) or '–'} |", flush=True)
    return m, o


def sparse_twins(ramp_every: int, hold_every: int, sensors: int, seed: int) -> None:
    """``--sparse-ramp-every``: twin ramps with long holds, sparse (module docstring)."""
    import numpy as np

    from simulators.ramp_sim import RampProfile, ramp_twin_sensors, simulate_ramp

    truths, taus = ramp_twin_sensors(sensors, seed, hysteresis_ug=15.0)
    profile = RampProfile(edge_hold_min=HOLD_MIN)
    runs = simulate_ramp(truths, taus, profile, seed=seed + 100, temp_row_noise_c=0.1,
                         temp_lsb_c=0.11)
    sse_m = sse_o = 0.0
    for i, run in enumerate(runs):
        held = np.flatnonzero((np.abs(run.die_c - profile.start_c) < 0.5)
                              | (np.abs(run.die_c - profile.peak_c) < 0.5))
        moving = np.setdiff1d(np.arange(len(run.recording)), held)
        rec = run.recording.subset(np.union1d(held[::hold_every], moving[::ramp_every]))
        m, o = _fit_row(f"1/{ramp_every}", i, rec, run.truth, seed + 400 + i)
        sse_m += m
        sse_o += o
    if sse_o:
        print(f"| 1/{ramp_every} | pooled ||||||||| {np.sqrt(sse_m / sse_o):.3f} | |",
              flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sim-speed", type=float, nargs="+", default=[3000.0, 40000.0, 80000.0])
    ap.add_argument("--sparse-ramp-every", type=int, nargs="+", default=[])
    ap.add_argument("--hold-every", type=int, default=7)
    ap.add_argument("--fit-csv", type=Path, nargs="+", default=[],
                    help="fit these recordings (e.g. --save-dir's) with the solves counted")
    ap.add_argument("--sensors", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--save-dir", type=Path, default=None,
                    help="write each campaign's fitted recording here (ramp_<k>_<speed>.csv)")
    args = ap.parse_args()
    if args.sparse_ramp_every or args.fit_csv:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        print("| ramp rows kept | sensor | rows | all-row solves (nfev) | fold-refit LM "
              "fallbacks (nfev) | "
              "each fallback's nfev | fit_continuous CPU, s | degree | held-out rms, µg | "
              "RMSE after, mg | held-out / oracle | degrees not judged |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for n in args.sparse_ramp_every:
            sparse_twins(n, args.hold_every, args.sensors, args.seed)
        if args.fit_csv:
            from calibration.recording import read_recording

            for k, path in enumerate(args.fit_csv):
                _fit_row(path.name, k, read_recording(path))
        return 0
    print("| sim speed | state | rows | all-row solves (nfev) | fold-refit LM fallbacks "
          "(nfev) | each fallback's nfev | CPU in LM, s | fit_continuous CPU, s | degree | "
          "held-out rms, µg | RMSE after, mg | degrees not judged |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k, speed in enumerate(args.sim_speed):
        SOLVES.clear()
        NFEV.clear()
        CPU_S.clear()
        FALLBACKS.clear()
        save = None if args.save_dir is None else args.save_dir / f"ramp_{k}_{speed:g}.csv"
        state, rows, s = run_campaign(speed, save)
        a, f = "all-row solve", "fold refit (LM fallback)"
        print(f"| {speed:g}× | {state} | {rows} | {SOLVES[a]} ({NFEV[a]}) | {SOLVES[f]} "
              f"({NFEV[f]}) | {', '.join(FALLBACKS) or '–'} | {CPU_S[a] + CPU_S[f]:.2f} | "
              f"{CPU_S['fit_continuous (whole)']:.2f} | {s.get('degree')} | "
              f"{s.get('heldout_ug')} | {s.get('rmse_after_mg')} | "
              f"{'; '.join(s.get('not_judged', [])) or '–'} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
