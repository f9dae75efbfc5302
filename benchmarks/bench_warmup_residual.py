"""What a warm-up's held-out error is made of: the noise of a 5-s mean, or model error.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.bench_warmup_residual \\
        --log FILE --import-args "..." [--draws 40] [--seed 0] [--out DIR]

The log is read and split as :mod:`benchmarks.bench_warmup_peers` reads and splits a
``--log`` (10-s blocks alternately fit and held out; the figure per axis the RMS of the
held-out 5-s means less the mean of the compensated fit samples). Then:

* **Each 5-s mean** (fit and held out): its time, mean temperature, dT/dt (°C/min, the
  derivative of a local parabola of the 1-s temperatures over :data:`RATE_WINDOW_S`), and
  its residual per axis uncompensated, through soakcal (``calibrate`` on the fit blocks,
  ``compensate``, :func:`benchmarks.bench_warmup_peers.method_soakcal`) and through
  ArduPilot's method. A smooth leftover against T says the thermal model is short; one
  against t a drift not in T; one against dT/dt a rate term.
* **Still and changing**: the held-out means split at |dT/dt| < :data:`STILL_C_PER_MIN`;
  each part's RMS, and on the still part the mean of the held-out means less that of the
  fit means at the same (still) temperatures: no function of temperature can move it, so
  it is the split's own noise at a 20-s period (its standard error from the still part's
  10-s Allan deviation, 7 + 7 blocks → σ₁₀·√2·√(2/n)).
* **Allan deviation** of the still samples (|dT/dt| < :data:`STILL_C_PER_MIN`, the
  longest such run) at 0.1 … 20 s: the white noise (τ^-½) and the part's own slow noise.
* **The method's figure when the model is exactly right** (``--draws``): a truth
  (soakcal's model fitted on the whole log, in its family: the smooth part in T and
  dT/dt the log shows) plus noise with the still run's spectrum (phase-randomised
  surrogates of its samples, each axis its own), scored as the log is: uncompensated
  less the truth (the **oracle**: what a perfect compensation scores on this split) and
  through soakcal and ArduPilot fitted on the draw. The log's figure beside that
  distribution (median, 10-90 %) says whether anything above the noise is left to gain.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_warmup_peers import (  # noqa: E402
    BLOCK_S,
    MEAN_S,
    ROW_S,
    WarmupLog,
    blocks,
    heldout_rms_mg,
    imported_log,
    method_ardupilot,
    method_soakcal,
    noise_floor_mg,
    rows_1s,
)
from calibration.temperature_conditioning import temperature_rate_c_per_min  # noqa: E402

RATE_WINDOW_S = 40.0
STILL_C_PER_MIN = 1.0
ALLAN_TAUS_S = (0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0)


def rate_per_sample(log: WarmupLog) -> np.ndarray:
    """dT/dt (°C/min) at each sample: the 1-s mean temperatures' local-parabola slope."""
    sec = np.floor(log.t_s - log.t_s[0]).astype(int)
    n = np.bincount(sec)
    have = n > 0
    t1 = (np.bincount(sec, log.t_s) / np.maximum(n, 1))[have]
    T1 = (np.bincount(sec, log.temp_c) / np.maximum(n, 1))[have]
    return np.interp(log.t_s, t1, temperature_rate_c_per_min(t1, T1, RATE_WINDOW_S))


def five_s_table(log: WarmupLog, methods: dict[str, np.ndarray]
                 ) -> tuple[list[dict[str, object]], np.ndarray]:
    """Every full 5-s mean: t, T, dT/dt, held out or fit, and each method's residual (mg,
    the compensated mean less the mean of the compensated fit samples)."""
    _, fit = blocks(log.t_s)
    half = np.floor((log.t_s - log.t_s[0]) / MEAN_S).astype(int)
    rate = rate_per_sample(log)
    per_s = (log.t_s.size - 1) / (log.t_s[-1] - log.t_s[0])
    refs = {k: v[fit].mean(axis=0) for k, v in methods.items()}
    rows = []
    for h in np.unique(half):
        m = half == h
        if m.sum() <= 0.8 * MEAN_S * per_s:
            continue
        row: dict[str, object] = {
            "t_s": float(log.t_s[m].mean() - log.t_s[0]), "T_c": float(log.temp_c[m].mean()),
            "rate_c_per_min": float(rate[m].mean()), "held_out": bool(not fit[m][0])}
        for k, v in methods.items():
            row[k] = [float(e) for e in (v[m].mean(axis=0) - refs[k]) * 1e3]
        rows.append(row)
    return rows, rate


def still_run(log: WarmupLog, rate: np.ndarray) -> np.ndarray | None:
    """Mask of the longest run of samples with |dT/dt| < STILL_C_PER_MIN (None: none)."""
    still = np.abs(rate) < STILL_C_PER_MIN
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    starts, ends = edges[::2], edges[1::2]
    if starts.size == 0:
        return None
    i = int(np.argmax(ends - starts))
    mask = np.zeros(still.size, bool)
    mask[starts[i]: ends[i]] = True
    return mask


def allan_mg(samples_g: np.ndarray, per_s: float) -> dict[str, list[float | None]]:
    """Per τ: the Allan deviation (mg) of each axis (non-overlapping, None below 3 means)."""
    out: dict[str, list[float | None]] = {}
    for tau in ALLAN_TAUS_S:
        m = int(round(tau * per_s))
        nb = samples_g.shape[0] // m
        if nb < 3:
            out[f"{tau:g}"] = [None, None, None]
            continue
        means = samples_g[: nb * m].reshape(nb, m, 3).mean(axis=1)
        out[f"{tau:g}"] = [float(v) for v in
                           np.sqrt(0.5 * np.mean(np.diff(means, axis=0) ** 2, axis=0)) * 1e3]
    return out


def split_parts(rows: list[dict[str, object]], method: str) -> dict[str, object]:
    """The held-out RMS, still and changing, and the still part's fit/held-out offset."""
    held = [r for r in rows if r["held_out"]]
    still_h = np.array([r[method] for r in held if abs(r["rate_c_per_min"]) < STILL_C_PER_MIN])
    moving_h = np.array([r[method] for r in held if abs(r["rate_c_per_min"]) >= STILL_C_PER_MIN])
    still_f = np.array([r[method] for r in rows if not r["held_out"]
                        and abs(r["rate_c_per_min"]) < STILL_C_PER_MIN])

    def rms(a: np.ndarray) -> list[float] | None:
        return None if a.size == 0 else [float(v) for v in np.sqrt(np.mean(a ** 2, axis=0))]

    return {"n_still": int(still_h.shape[0]), "n_changing": int(moving_h.shape[0]),
            "rms_still_mg": rms(still_h), "rms_changing_mg": rms(moving_h),
            "still_offset_mg": (None if still_h.size == 0 or still_f.size == 0 else
                                [float(v) for v in still_h.mean(axis=0) - still_f.mean(axis=0)]),
            "sum_sq_still_mg2": None if still_h.size == 0 else
            [float(v) for v in np.sum(still_h ** 2, axis=0)],
            "sum_sq_changing_mg2": None if moving_h.size == 0 else
            [float(v) for v in np.sum(moving_h ** 2, axis=0)]}


def leftover_slopes(rows: list[dict[str, object]], method: str) -> dict[str, object]:
    """Least-squares slopes of the held-out residuals (mg) per axis, ± standard error:
    against T (°C) and dT/dt (°C/min) over all held-out means, against t (per 100 s) over
    the still ones (T constant there: a drift in time, not in T)."""
    held = [r for r in rows if r["held_out"]]
    out: dict[str, object] = {}
    for name, key, still_only, unit in (("T", "T_c", False, 1.0),
                                        ("dT/dt", "rate_c_per_min", False, 1.0),
                                        ("t (still)", "t_s", True, 100.0)):
        use = [r for r in held if not still_only
               or abs(r["rate_c_per_min"]) < STILL_C_PER_MIN]  # type: ignore[arg-type]
        if len(use) < 4:
            out[name] = None
            continue
        x = np.array([r[key] for r in use], float) / unit
        y = np.array([r[method] for r in use], float)
        X = np.column_stack([np.ones(x.size), x - x.mean()])
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        s2 = np.sum((y - X @ beta) ** 2, axis=0) / (x.size - 2)
        se = np.sqrt(s2 / np.sum((x - x.mean()) ** 2))
        out[name] = {"slope": [float(v) for v in beta[1]], "stderr": [float(v) for v in se]}
    return out


FAMILY_WINDOWS_S = (10.0, 20.0, 40.0, 80.0)
FAMILY_LAGS_S = (10.0, 20.0, 30.0)


def families(log: WarmupLog) -> list[dict[str, object]]:
    """Fixed model families fitted as soakcal fits a warm-up (least squares on the fit
    blocks' 1-s rows at their own mean temperatures, x = (T − mid) / max(half span, 1 °C);
    applied at each 1-s row's temperature clamped to the fit rows' span, a rate column
    unclamped) and scored on the split: degree 1-3 alone; with a rate term k·dT/dt (dT/dt
    over each of :data:`FAMILY_WINDOWS_S`, gain constant, and at 40 s of degree 1 in x);
    and a lagging channel, the polynomial in T + τ·dT/dt (τ in :data:`FAMILY_LAGS_S`,
    dT/dt over 40 s)."""
    _, fit = blocks(log.t_s)
    rows = np.asarray(rows_1s(log, np.ones(log.t_s.size, bool)))
    t1, T1, A1 = rows[:, 0], rows[:, 1], rows[:, 2:5]
    fitrow = np.floor((t1 - log.t_s[0]) / BLOCK_S).astype(int) % 2 == 0
    lo, hi = float(T1[fitrow].min()), float(T1[fitrow].max())
    centre, scale = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1.0)
    sec = np.floor((log.t_s - log.t_s[0]) / ROW_S).astype(int)
    row_of_sec = np.full(int(sec.max()) + 1, -1)
    row_of_sec[np.floor(t1 - log.t_s[0]).astype(int)] = np.arange(t1.size)
    idx = row_of_sec[sec]

    def scored(degree: int, window: float | None = None, gain_degree: int = 0,
               lag_s: float | None = None) -> list[float]:
        def columns(T: np.ndarray, rate: np.ndarray | None) -> np.ndarray:
            x = (T - centre) / scale
            cols = [np.vander(x, degree + 1, increasing=True)]
            if rate is not None and lag_s is None:
                cols.append(rate[:, None] * np.vander(x, gain_degree + 1, increasing=True))
            return np.hstack(cols)
        r_fit = r_all = None
        if window is not None:
            r_fit = temperature_rate_c_per_min(t1[fitrow], T1[fitrow], window)
            r_all = temperature_rate_c_per_min(t1, T1, window)
        T_fit, T_all = T1[fitrow], T1
        if lag_s is not None:  # the die leads the channel by τ·dT/dt
            T_fit = T_fit + lag_s * r_fit / 60.0  # type: ignore[operator]
            T_all = T_all + lag_s * r_all / 60.0  # type: ignore[operator]
        beta, *_ = np.linalg.lstsq(columns(T_fit, r_fit), A1[fitrow], rcond=None)
        pred = columns(np.clip(T_all, lo, hi), r_all)[:, 1:] @ beta[1:]
        comp = np.where((idx >= 0)[:, None], log.acc_g - pred[np.maximum(idx, 0)], np.nan)
        return [float(v) for v in heldout_rms_mg(log, comp)]

    out: list[dict[str, object]] = []
    for d in (1, 2, 3):
        out.append({"model": f"degree {d}", "heldout_mg": scored(d)})
        out += [{"model": f"degree {d} + k·dT/dt ({w:g} s)", "heldout_mg": scored(d, w)}
                for w in FAMILY_WINDOWS_S]
        out.append({"model": f"degree {d} + k(T)·dT/dt, k of degree 1 (40 s)",
                    "heldout_mg": scored(d, 40.0, 1)})
        out += [{"model": f"degree {d} in T + {tau:g} s·dT/dt (40 s)",
                 "heldout_mg": scored(d, 40.0, lag_s=tau)} for tau in FAMILY_LAGS_S]
    return out


def surrogate(noise_g: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) Gaussian noise whose power spectrum is the periodogram of ``noise_g`` (each
    axis its own, mean removed) interpolated to n samples' frequencies: complex Gaussian
    Fourier coefficients of that power."""
    m = noise_g.shape[0]
    out = np.empty((n, 3))
    f_in = np.fft.rfftfreq(m)
    f_out = np.fft.rfftfreq(n)
    for a in range(3):
        y = noise_g[:, a] - noise_g[:, a].mean()
        psd = np.abs(np.fft.rfft(y)) ** 2 / m  # per-sample power density
        psd_out = np.interp(f_out, f_in, psd)
        psd_out[0] = 0.0
        spec = np.sqrt(psd_out * n / 2.0) * (rng.standard_normal(f_out.size)
                                             + 1j * rng.standard_normal(f_out.size))
        out[:, a] = np.fft.irfft(spec, n)
    return out


def draws(log: WarmupLog, truth_g: np.ndarray, noise_g: np.ndarray, count: int, seed: int,
          workdir: Path) -> dict[str, list[list[float]]]:
    """Per draw, per method: the held-out RMS (mg) of truth + surrogate noise."""
    rng = np.random.default_rng(seed)
    got: dict[str, list[list[float]]] = {"oracle": [], "soakcal": [], "ardupilot": []}
    for i in range(count):
        noise = surrogate(noise_g, log.t_s.size, rng)
        d = WarmupLog(f"draw{i}", log.t_s, truth_g + noise, log.temp_c)
        got["oracle"].append([float(v) for v in heldout_rms_mg(d, noise)])
        soak, _ = method_soakcal(d, workdir)
        got["soakcal"].append([float(v) for v in heldout_rms_mg(d, soak)]
                              if soak is not None else [float("nan")] * 3)
        got["ardupilot"].append([float(v) for v in heldout_rms_mg(d, method_ardupilot(d)[0])])
        print(json.dumps({k: v[-1] for k, v in got.items()}), flush=True)
    return got


def pct(values: list[list[float]]) -> dict[str, list[float]]:
    a = np.asarray(values, float)
    return {"p10": [float(v) for v in np.nanpercentile(a, 10, axis=0)],
            "median": [float(v) for v in np.nanmedian(a, axis=0)],
            "p90": [float(v) for v in np.nanpercentile(a, 90, axis=0)]}


def xyz(v: list[float | None] | list[float] | None, digits: int = 3) -> str:
    if v is None or any(e is None for e in v):
        return "—"
    return " / ".join(f"{e:.{digits}f}" for e in v)


def report(res: dict[str, object]) -> str:
    lines = [f"log: {res['log']}", "",
             "| t s | T °C | dT/dt °C/min | split | none z | soakcal x / y / z | ArduPilot z |",
             "|---|---|---|---|---|---|---|"]
    for r in res["means"]:  # type: ignore[union-attr]
        lines.append(f"| {r['t_s']:.1f} | {r['T_c']:.3f} | {r['rate_c_per_min']:.2f} | "
                     f"{'held' if r['held_out'] else 'fit'} | {r['none'][2]:.3f} | "
                     f"{xyz(r['soakcal'])} | {r['ardupilot'][2]:.3f} |")
    lines += ["", "| method | held-out RMS | still: n, RMS | changing: n, RMS | "
              "still held − fit |", "|---|---|---|---|---|"]
    for k, p in res["parts"].items():  # type: ignore[union-attr]
        lines.append(f"| {k} | {xyz(res['heldout_mg'][k])} | {p['n_still']}, "  # type: ignore[index]
                     f"{xyz(p['rms_still_mg'])} | {p['n_changing']}, "
                     f"{xyz(p['rms_changing_mg'])} | {xyz(p['still_offset_mg'])} |")
    lines += ["", "Held-out residual slopes, mg per unit ± standard error, x / y / z:", ""]
    for k, sl in res["slopes"].items():  # type: ignore[union-attr]
        for name, v in sl.items():
            unit = {"T": "°C", "dT/dt": "°C/min", "t (still)": "100 s"}[name]
            lines.append(f"- {k}, against {name} (per {unit}): " + (
                "—" if v is None else " / ".join(
                    f"{b:+.3f} ± {e:.3f}" for b, e in zip(v["slope"], v["stderr"], strict=True))))
    lines += ["", f"floor (two 5-s means of a held-out block ÷ √2): {xyz(res['floor_mg'])} mg",
              f"still run: {res['still_s']:.0f} s; Allan deviation, mg x / y / z:", ""]
    lines += [f"- τ = {tau} s: {xyz(v)}" for tau, v in res["allan_mg"].items()]  # type: ignore[union-attr]
    if "families" in res:
        lines += ["", "Fixed model families on the split (held-out RMS, mg x / y / z):", "",
                  "| model | held-out |", "|---|---|"]
        lines += [f"| {f['model']} | {xyz(f['heldout_mg'], 4)} |"  # type: ignore[arg-type]
                  for f in res["families"]]  # type: ignore[union-attr]
    if "draws" in res:
        lines += ["", f"{res['n_draws']} draws: truth = soakcal on the whole log, noise = "
                      "the still run's spectrum (held-out RMS, mg x / y / z):", "",
                  "| method | p10 | median | p90 | the log |", "|---|---|---|---|---|"]
        for k, p in res["draws"].items():  # type: ignore[union-attr]
            seen = res["heldout_mg"].get(k, res["heldout_mg"]["none"]  # type: ignore[union-attr]
                                         if k == "oracle" else None)
            lines.append(f"| {k} | {xyz(p['p10'])} | {xyz(p['median'])} | {xyz(p['p90'])} | "
                         f"{xyz(seen) if k != 'oracle' else '—'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--log", type=Path, required=True)
    ap.add_argument("--log-format", choices=("ulog", "dataflash", "csv"), default="csv")
    ap.add_argument("--import-args", default="")
    ap.add_argument("--draws", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--families", action="store_true",
                    help="also fixed model families scored on the split (families())")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        log, said = imported_log(args.log, args.log_format, shlex.split(args.import_args), work)
        if log is None:
            print(f"{args.log.name}: {said}")
            return 2
        soak, note = method_soakcal(log, work)
        if soak is None:
            print(f"soakcal: {note}")
            return 2
        methods = {"none": log.acc_g, "soakcal": soak, "ardupilot": method_ardupilot(log)[0]}
        rows, rate = five_s_table(log, methods)
        still = still_run(log, rate)
        per_s = (log.t_s.size - 1) / (log.t_s[-1] - log.t_s[0])
        res: dict[str, object] = {
            "log": log.name, "means": rows,
            "heldout_mg": {k: [float(e) for e in heldout_rms_mg(log, v)]
                           for k, v in methods.items()},
            "parts": {k: split_parts(rows, k) for k in methods},
            "slopes": {k: leftover_slopes(rows, k) for k in ("soakcal", "ardupilot")},
            "floor_mg": [float(v) for v in noise_floor_mg(log)],
            "still_s": 0.0 if still is None else float(still.sum() / per_s),
            "allan_mg": {} if still is None else allan_mg(log.acc_g[still], per_s)}
        if args.families:
            res["families"] = families(log)
        if args.draws and still is None:
            print("no still run: no noise spectrum for the draws")
        elif args.draws:
            whole, _ = method_soakcal(log, work, fit=np.ones(log.t_s.size, bool))
            if whole is None:
                print("soakcal on the whole log refused: no truth for the draws")
                return 2
            truth = log.acc_g - whole + whole.mean(axis=0)  # the model's change, at g
            noise = log.acc_g[still] - truth[still]
            got = draws(log, truth, noise, args.draws, args.seed, work)
            res["n_draws"] = args.draws
            res["draws"] = {k: pct(v) for k, v in got.items()}
            res["draw_values"] = got
    text = report(res)
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "results.json").write_text(json.dumps(res, indent=2))
        (args.out / "table.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
