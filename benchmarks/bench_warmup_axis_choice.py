"""Each axis' held-out error per warm-up model: the joint choice beside a per-axis one.

Usage::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.bench_warmup_axis_choice \\
        [--out DIR] [--realdata DIR] [--log FILE ... [--import-args "..."]] [--no-twin]

The logs are ``bench_warmup_peers``' (its twins and BMI270 logs unless ``--no-twin``, and
every ``--log`` through ``soakcal import``), and so is the fit half: the 10-s fit blocks'
1-s mean rows (:func:`benchmarks.bench_warmup_peers.rows_1s`). ``calibration.fitting.fit``
runs on them as ``soakcal calibrate`` does; the capture means it hands the warm-up solver
(:func:`calibration.warmup.fit_warmup`) are kept, and on them, with the solver's own
held-out folds (:func:`calibration.warmup._folds`: alternate temperature blocks), this
prints per axis x / y / z:

* the held-out RMS (mg) of every model the solver weighs: degree 0 … 3 without a rate term
  and each identified (degree d, rate-gain degree m), :func:`calibration.warmup._heldout_errors_g`;
* the model the solver keeps per axis (``calibrate --json``'s ``axis_choice``: one model
  chosen on the three axes' sum, an axis held where that model does not lower its own
  held-out error beyond the gain's standard error);
* the model each axis would get if every step of that choice ran on its own held-out error
  alone (:func:`per_axis_choice`: the degree by :func:`calibration.warmup._choose_degree`,
  else a rate model by :func:`calibration.warmup._rate_beats`, then the model of the
  change by :func:`calibration.warmup._choose_model`): what PX4's and ArduPilot's scripts
  do, each axis fitted on its own.

This says which model each rule picks and on what held-out figures; what the picked
models score on the benchmark's own held-out 5-s means is ``bench_warmup_peers``' figure
(docs/benchmarks.md, "Each axis its own model").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_warmup_peers import (  # noqa: E402
    WarmupLog,
    _write_rows,
    add_log_arguments,
    blocks,
    evaluate_logs,
    rows_1s,
    write_results,
)
from calibration import warmup  # noqa: E402
from calibration.errors import CalibrationError  # noqa: E402
from calibration.fitting import fit  # noqa: E402
from calibration.recording import read_recording  # noqa: E402

Errors = tuple[np.ndarray, np.ndarray]


def per_axis_choice(axis: int, errors: list[Errors], rate_errors: list[Errors],
                    candidates: list[tuple[int, int]], block: np.ndarray
                    ) -> tuple[int, int | None]:
    """(degree, rate-gain degree or None) for one axis, every step of the warm-up
    solver's choice run on that axis' held-out errors alone."""
    own = [(e[:, [axis]], i) for e, i in errors]
    own_rate = [(e[:, [axis]], i) for e, i in rate_errors]
    totals = [_rms(e) for e, _ in own]
    with_rate = [_rms(e) for e, _ in own_rate]
    degree = warmup._choose_degree([e for e, _ in own], errors[0][1], block)
    best = warmup._choose(with_rate) if with_rate else None
    established = degree > 0 or (best is not None
                                 and warmup._rate_beats(own[0], own_rate[best], block))
    if not established:
        return 0, None
    degree, index = warmup._choose_model(totals, with_rate, candidates)
    return (degree, None) if index is None else candidates[index]


def _rms(errors_g: np.ndarray) -> float:
    return float(np.sqrt(np.mean(errors_g ** 2))) if errors_g.size else float("nan")


def analyse(log: WarmupLog, workdir: Path) -> dict[str, Any]:
    """The fit half of ``log`` through ``fit``; each model's held-out RMS per axis, the
    solver's choice and the per-axis one (or why the log was refused)."""
    _, fitted = blocks(log.t_s)
    path = workdir / "fit.csv"
    _write_rows(path, rows_1s(log, fitted))
    seen: dict[str, Any] = {}
    solver = warmup.fit_warmup

    def spy(captures: Any, orientations: Any, **kw: Any) -> warmup.WarmupFit:
        seen.update(captures=captures, orientations=orientations, kw=kw)
        return solver(captures, orientations, **kw)

    warmup.fit_warmup = spy  # type: ignore[assignment]
    try:
        report = fit(read_recording(path)).report
    except CalibrationError as exc:
        return {"log": log.name, "refused": str(exc).splitlines()[0][:300]}
    finally:
        warmup.fit_warmup = solver  # type: ignore[assignment]
    if report.get("mode") != "warmup" or "captures" not in seen:
        return {"log": log.name, "refused": f"not a warm-up fit (mode {report.get('mode')})"}
    cap, orientations, kw = seen["captures"], seen["orientations"], seen["kw"]
    T, raw, labels = cap.temperature_c(), cap.raw_g, orientations.labels
    lo, hi = kw.get("span_c") or (float(np.min(T)), float(np.max(T)))
    x = (T - 0.5 * (lo + hi)) / max(0.5 * (hi - lo), 1.0)
    folds, block = warmup._folds(T), warmup._block_index(T)
    top = int(report["degree_selection"][-1]["degree"])
    errors = [warmup._heldout_errors_g(x, labels, raw, folds, d) for d in range(top + 1)]
    candidates = [(int(r["degree"]), int(r["gain_degree"])) for r in report["rate_selection"]]
    rate_errors: list[Errors] = []
    if candidates:
        window = float(report["rate_identifiability"]["window_s"])
        rate = warmup.temperature_rate_c_per_min(cap.t_s, T, window)
        rate_errors = [warmup._heldout_errors_g(x, labels, raw, folds, d,
                                                warmup._rate_columns(rate, x, m))
                       for d, m in candidates]
    models = {f"d={d}": _mg(e) for d, (e, _) in enumerate(errors)}
    models.update({f"d={d}, m={m}": _mg(e)
                   for (d, m), (e, _) in zip(candidates, rate_errors, strict=True)})
    gains = (report.get("rate_term") or {}).get("gain_ug_per_c_per_min")
    kept = {n: (c["degree"], len(gains[a]) - 1 if c.get("rate_term") and gains else None)
            for a, (n, c) in enumerate(report["axis_choice"].items())}
    own = {n: per_axis_choice(a, errors, rate_errors, candidates, block)
           for a, n in enumerate(("bx", "by", "bz"))}
    return {"log": log.name, "captures": len(cap), "models_heldout_mg_xyz": models,
            "kept": kept, "per_axis": own}


def _mg(errors_g: np.ndarray) -> list[float]:
    return [round(float(np.sqrt(np.mean(errors_g[:, a] ** 2))) * 1e3, 4)
            if errors_g.size else float("nan") for a in range(3)]


def _said(choice: tuple[int, int | None]) -> str:
    d, m = choice
    return f"d={d}" if m is None else f"d={d}, m={m}"


def table(results: list[dict[str, Any]]) -> str:
    """Markdown: per log, every model's held-out RMS x / y / z, the kept and per-axis
    choices."""
    out = []
    for r in results:
        out.append(f"**{r['log']}**" + (f": refused ({r['refused']})" if "refused" in r
                                         else f" ({r['captures']} capture means)"))
        if "refused" in r:
            out.append("")
            continue
        out += ["", "| model | held-out RMS x / y / z (mg) |", "|---|---|"]
        out += [f"| {k} | {' / '.join(f'{v:.4f}' for v in vals)} |"
                for k, vals in r["models_heldout_mg_xyz"].items()]
        out += ["", "kept (joint model, each axis held or simplified on its own error): "
                + "; ".join(f"{n} {_said(c)}" for n, c in r["kept"].items()),
                "each axis by its own held-out error alone: "
                + "; ".join(f"{n} {_said(c)}" for n, c in r["per_axis"].items()), ""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, help="write results.json and table.md here")
    add_log_arguments(ap)
    args = ap.parse_args(argv)
    results = evaluate_logs(args, analyse, default=str)
    text = table([r for r in results if "unusable" not in r])
    print(text)
    write_results(args.out, results, text, default=str)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
