"""A capture mean's temperature noise: from the capture means' own second differences beside
what each capture's own samples say (:func:`calibration.temperature_conditioning.
capture_temperature_noise`), and the warm-up's rate check with each.

Usage::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.bench_capture_temperature_noise \\
        [--out DIR] [--realdata DIR] [--log FILE ... [--import-args "..."]] [--no-twin]

The logs are ``bench_warmup_peers``' (its twins and BMI270 logs unless ``--no-twin``, and
every ``--log`` through ``soakcal import``). Each is read as ``soakcal calibrate`` reads
raw rows (:func:`calibration.captures.capture_means`: 5-s capture means), twice: the
benchmark's fit blocks (alternate 10-s blocks, two captures per block, 5 and 15 s apart:
the split of ``bench_warmup_peers --whole``) and the whole log (captures every 5 s).

Per log this prints, in °C:

* ``sigma(tau)``: the noise SD of a tau-s mean temperature, from second differences of
  consecutive tau-s means (the estimator of :func:`calibration.temperature_conditioning.
  temperature_noise_c`), never across two captures for tau below the capture, and over the
  whole log's consecutive means for tau of 5 s and more. White noise gives sigma(tau)
  proportional to tau^-1/2; a channel whose noise does not average down beyond a second
  (flicker, or the die's own wander) gives a flat or rising curve;
* ``series``: :func:`temperature_noise_c` on the fit split's capture means and on the
  whole log's (what the rate check used before the captures' own samples were read);
* ``own``: :func:`capture_temperature_noise` on the fit split (its white-noise ratio, and
  the per-capture noise where it is used);
* the rate check's outcome (``calibrate --json``'s ``rate_identifiability``) on the fit
  split: as ``calibrate`` runs it, and with the captures' own samples ignored (the capture
  means' second differences: the rate check before).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_warmup_peers import (  # noqa: E402
    WarmupLog,
    add_log_arguments,
    blocks,
    evaluate_logs,
    write_results,
)
from calibration import captures as captures_module  # noqa: E402
from calibration import temperature_conditioning as tc  # noqa: E402
from calibration.captures import capture_means  # noqa: E402
from calibration.errors import CalibrationError  # noqa: E402
from calibration.fitting import fit  # noqa: E402
from calibration.recording import Recording  # noqa: E402

SUB_TAUS_S = (0.25, 0.5, 1.0, 5.0 / 3.0)  # inside a 5-s capture (3 or more per capture)
LONG_TAUS_S = (5.0, 10.0, 20.0)  # over the whole log's consecutive means


def raw_recording(log: WarmupLog, mask: np.ndarray) -> Recording:
    """The masked samples as ``soakcal import`` writes a raw log (one row per sample)."""
    return Recording.from_columns({
        "t_s": log.t_s[mask], "sensor_c": log.temp_c[mask], "ax": log.acc_g[mask, 0],
        "ay": log.acc_g[mask, 1], "az": log.acc_g[mask, 2], "n": np.ones(int(mask.sum()))},
        path=log.name)


def within_capture_sigma_c(t_s: np.ndarray, temp_c: np.ndarray, group: np.ndarray,
                           tau_s: float) -> tuple[float, int]:
    """The noise SD of a ``tau_s`` mean from second differences of full sub-means inside
    one capture (never across two), pooled (the product's estimator,
    :func:`calibration.temperature_conditioning._second_difference_noise_c`); and how many
    second differences it rests on."""
    ok = (group >= 0) & np.isfinite(temp_c)
    t, y, g = t_s[ok], temp_c[ok], group[ok].astype(np.int64)
    start = np.full(int(g.max()) + 1, np.inf)
    np.minimum.at(start, g, t)
    sub = np.floor((t - start[g]) / tau_s).astype(np.int64)
    key = g * (int(sub.max()) + 1) + sub
    first = np.r_[0, np.flatnonzero(np.diff(key)) + 1]
    counts = np.diff(np.r_[first, key.size])
    means, owner = np.add.reduceat(y, first) / counts, g[first]
    full = counts >= 0.8 * np.median(counts)
    same = (owner[2:] == owner[:-2]) & full[2:] & full[1:-1] & full[:-2]
    second = (means[2:] - 2.0 * means[1:-1] + means[:-2])[same]
    if second.size < 3:
        return math.nan, int(second.size)
    return tc._second_difference_noise_c(second), int(second.size)


def long_sigma_c(t_s: np.ndarray, temp_c: np.ndarray, tau_s: float) -> float:
    """The noise SD of consecutive ``tau_s`` means over a contiguous log:
    :func:`calibration.temperature_conditioning.temperature_noise_c` on them (its robust SD
    of second differences discounts the few triplets where the warm-up turns)."""
    k = np.floor((t_s - t_s[0]) / tau_s).astype(np.int64)
    n = np.bincount(k)
    full = n >= 0.8 * np.median(n[n > 0])
    means = np.bincount(k, weights=temp_c) / np.maximum(n, 1)
    return tc.temperature_noise_c(np.flatnonzero(full) * tau_s, means[full])


@contextmanager
def series_noise_only(active: bool) -> Iterator[None]:
    """Within the block (when ``active``), the warm-up fit gets no own-sample noise
    (:func:`calibration.captures.own_temperature_noise`), so the rate check reads the
    capture means' second differences, as before."""
    if not active:
        yield
        return
    saved = captures_module.own_temperature_noise
    captures_module.own_temperature_noise = lambda *a, **k: None  # type: ignore[assignment]
    try:
        yield
    finally:
        captures_module.own_temperature_noise = saved  # type: ignore[assignment]


def rate_check(rec: Recording, series_only: bool) -> dict[str, Any]:
    """``fit``'s warm-up model on ``rec``: its rate check, degree and rate term."""
    with series_noise_only(series_only):
        try:
            res = fit(rec)
        except CalibrationError as exc:
            return {"refused": str(exc)[:200]}
    ident = res.report.get("rate_identifiability") or {}
    rate = res.model.temperature_rate
    return {"tried": ident.get("tried"), "window_s": ident.get("window_s"),
            "noise_c_per_min": ident.get("noise_c_per_min"),
            "residual_rms_c_per_min": ident.get("residual_rms_c_per_min"),
            "temperature_noise": ident.get("temperature_noise"),
            "degree": res.report.get("degree"),
            "rate_term_kept": bool(rate),
            "heldout_rms_mg_xyz": res.report.get("heldout_rms_mg_xyz", {}).get("compensated"),
            "rate_selection": res.report.get("rate_selection")}


def evaluate(log: WarmupLog) -> dict[str, Any]:
    _, fit_mask = blocks(log.t_s)
    every = np.ones(log.t_s.size, bool)
    split, whole = raw_recording(log, fit_mask), raw_recording(log, every)
    caps_split, caps_whole = capture_means(split), capture_means(whole)
    out: dict[str, Any] = {"log": log.name}
    t_all, T_all = whole.t_s, whole.temperature_c()
    out["sigma_tau_c"] = {}
    for tau in SUB_TAUS_S:
        sigma, count = within_capture_sigma_c(t_all, T_all, caps_whole.row_capture, tau)
        out["sigma_tau_c"][f"{tau:.3g}"] = {"sigma": sigma, "second_differences": count}
    for tau in LONG_TAUS_S:
        out["sigma_tau_c"][f"{tau:.3g}"] = {"sigma": long_sigma_c(t_all, T_all, tau)}
    m_split, m_whole = caps_split.recording, caps_whole.recording
    out["series_split_c"] = tc.temperature_noise_c(m_split.t_s, m_split.temperature_c())
    out["series_whole_c"] = tc.temperature_noise_c(m_whole.t_s, m_whole.temperature_c())
    own = captures_module.own_temperature_noise(split, caps_split)
    out["own_white_ratio"] = None if own is None else own.white_ratio
    out["own_split_c"] = (None if own is None or own.per_capture_c is None
                          else float(np.nanmedian(own.per_capture_c)))
    out["rate_check"] = rate_check(split, series_only=False)
    out["rate_check_series"] = rate_check(split, series_only=True)
    return out


def table(results: list[dict[str, Any]]) -> str:
    taus = [f"{tau:.3g}" for tau in (*SUB_TAUS_S, *LONG_TAUS_S)]
    lines = ["| log | " + " | ".join(f"σ({t} s)" for t in taus)
             + " | series: split / whole | own: white ratio, split | rate check, series | "
               "rate check, calibrate |",
             "|---|" + "---|" * (len(taus) + 4)]

    def said(r: dict[str, Any]) -> str:
        if "refused" in r:
            return "refused"
        if not r["tried"]:
            return "not resolved"
        kept = "kept" if r["rate_term_kept"] else "not kept"
        return f"tried over {r['window_s']:g} s, {kept}"

    for r in results:
        if "unusable" in r:
            continue
        sig = " | ".join(f"{r['sigma_tau_c'][t]['sigma']:.4f}" for t in taus)
        ratio = "—" if r["own_white_ratio"] is None else f"{r['own_white_ratio']:.2f}"
        own = "not used" if r["own_split_c"] is None else f"{r['own_split_c']:.4f}"
        lines.append(f"| {r['log']} | {sig} | {r['series_split_c']:.4f} / "
                     f"{r['series_whole_c']:.4f} | {ratio}, {own} | "
                     f"{said(r['rate_check_series'])} | {said(r['rate_check'])} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, help="write results.json and table.md here")
    add_log_arguments(ap)
    args = ap.parse_args(argv)
    results = evaluate_logs(args, lambda log, _work: evaluate(log), default=float)
    text = table(results)
    print(text)
    write_results(args.out, results, text, default=float)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
