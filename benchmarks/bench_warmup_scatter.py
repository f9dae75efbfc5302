"""A warm-up's capture scatter against its noise, on the logs of ``bench_warmup_peers``.

Usage::

    .venv/bin/python -m benchmarks.bench_warmup_scatter [--out DIR] [--realdata DIR]
        [--log FILE ... [--log-format ulog|dataflash|csv] [--import-args "..."]] [--no-twin]

For each log (the twins and the BMI270 logs of :mod:`benchmarks.bench_warmup_peers`,
plus any ``--log``, imported the same way), ``soakcal calibrate --json`` on three cuts
of it: the whole log as raw rows, the fit blocks as raw rows (``--whole``'s held-out
path) and the fit blocks as 1-s rows (the benchmark's own path). Per cut: the exit
code, the degree and rate term chosen, and ``capture_scatter`` (the noise of one
capture mean, the RMS of the capture means about the model, the axes beyond the noise)
or the refusal's line. Run it on two trees to compare (a tree without
``capture_scatter`` shows its exit and degree only).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.bench_warmup_peers import (
    REPO,
    SOAKCAL,
    WarmupLog,
    _write_raw,
    _write_rows,
    add_log_arguments,
    blocks,
    gather_logs,
    rows_1s,
)


def calibrate_json(path: Path, workdir: Path) -> dict[str, object]:
    """``soakcal calibrate --json`` on ``path``: exit, degree, rate, scatter or refusal."""
    model = workdir / "scatter_model.json"
    run = subprocess.run([*SOAKCAL, "calibrate", str(path), "-o", str(model), "--json"],
                         capture_output=True, text=True, cwd=REPO)
    out: dict[str, object] = {"exit": run.returncode}
    if run.returncode != 0:
        out["refusal"] = (run.stderr.strip().splitlines() or [""])[-1]
        return out
    doc = json.loads(run.stdout)
    out["degree"] = doc.get("degree")
    out["rate_term"] = doc.get("rate_term") is not None
    out["capture_scatter"] = doc.get("capture_scatter")
    out["unexplained_mg"] = doc.get("unexplained_mg")
    return out


def evaluate(log: WarmupLog, workdir: Path) -> dict[str, object]:
    """The three cuts of one log (module docstring)."""
    _, fit = blocks(log.t_s)
    whole, fit_raw, fit_1s = (workdir / n for n in ("whole.csv", "fit_raw.csv", "fit_1s.csv"))
    _write_raw(whole, log, np.ones(log.t_s.size, bool))
    _write_raw(fit_raw, log, fit)
    _write_rows(fit_1s, rows_1s(log, fit))
    return {"log": log.name,
            "whole raw rows": calibrate_json(whole, workdir),
            "fit blocks, raw rows": calibrate_json(fit_raw, workdir),
            "fit blocks, 1-s rows": calibrate_json(fit_1s, workdir)}


def _cell(r: dict[str, object]) -> str:
    if r["exit"] != 0:
        return f"exit {r['exit']}: {str(r['refusal'])[7:90]}…"
    s = r.get("capture_scatter")
    head = f"d={r['degree']}{' +rate' if r['rate_term'] else ''}"
    if not isinstance(s, dict):
        return head
    if s.get("not_judged"):
        return f"{head}; not judged"

    def xyz(key: str) -> str:
        return "/".join("—" if v is None else f"{v:.4f}" for v in s[key])  # type: ignore[index]
    beyond = "".join(a for a, b in zip("xyz", s["beyond_noise_xyz"], strict=True) if b)
    return (f"{head}; noise {xyz('noise_mg_xyz')}; about the model "
            f"{xyz('residual_rms_mg_xyz')}; beyond: {beyond or 'none'}")


def table(results: list[dict[str, object]]) -> str:
    cuts = ("whole raw rows", "fit blocks, raw rows", "fit blocks, 1-s rows")
    lines = ["| log | " + " | ".join(cuts) + " |", "|---|---|---|---|"]
    for r in results:
        lines.append(f"| {r['log']} | " + " | ".join(_cell(r[c]) for c in cuts) + " |")  # type: ignore[arg-type]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, help="write scatter.json and scatter.md here")
    add_log_arguments(ap)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        logs, _ = gather_logs(args, Path(tmp))  # an unusable --log is said while importing
        results: list[dict[str, object]] = []
        for log in logs:
            results.append(evaluate(log, Path(tmp)))
            print(json.dumps(results[-1]), flush=True)
    text = table(results)
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "scatter.json").write_text(json.dumps(results, indent=2))
        (args.out / "scatter.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
