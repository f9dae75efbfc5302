"""Calibrated on one whole warm-up, flown on another: soakcal beside PX4 and ArduPilot.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.bench_warmup_second_log \\
        --realdata DIR [--cases 30] [--seed 1000] [--only 1026,...] [--no-twin] [--as-flown]
        [--out DIR]

``bench_warmup_peers`` and ``bench_warmup_gen2`` fit on alternate 10-s blocks of one log
and score the held-out blocks; the fit log then has gaps, and a rate term's dT/dt is
lower at them. A user calibrates on one whole warm-up and flies others. Here each case is
**two warm-ups of the same sensor** (:func:`second_case`: the same truth, another noise
seed and another temperature profile), every method is fitted on the whole first log and
scored on the whole second:

* ``px4``, ``ardupilot``: the peers' fits (:func:`benchmarks.bench_warmup_peers.method_px4`,
  ``method_ardupilot``) on every sample of the first log, applied at each sample's reading
  of the second, clamped to the first log's span as the firmwares clamp;
* ``soakcal``: ``soakcal calibrate`` on the first log's 1-s rows, ``soakcal compensate``
  of the second's (:func:`benchmarks.bench_warmup_peers.method_soakcal` with
  ``apply_to``: temperatures clamped to the fit span, a rate term from the unclamped ones);
* ``export px4`` / ``export ardupilot``: the files ``soakcal export --format px4|ardupilot``
  writes from that model, applied at each sample's reading by the firmware's formula
  (:func:`benchmarks.bench_warmup_peers.method_export`).

The figure per axis is the RMS of every full 5-s mean of the second log about their mean
(each method's constant removed: the gravity projection is an unknown constant), in mg:
against the logged data (as the benches score) and against the generator's truth (the
compensated truth, no noise). ``oracle``: the second log's noise alone scored the same way.
Per case soakcal ÷ the better peer, per axis, with a 95 % paired bootstrap over 60-s
windows of 5-s means (:func:`whole_ratio_interval`); the outcome is
``bench_warmup_gen2.verdict``'s (won: ≤ the better peer on every axis; within: ≤ peer +
10 % of the oracle). Beside it, for the same first log, the split's figure
(``split``: soakcal ÷ better peer held out on the first log's alternate blocks, as the
other benches score it). Where the second log goes beyond the first log's span, where
each method clamps at its own edge, the figure again on the 5-s means inside soakcal's
edges (:func:`beyond_span`).

``--as-flown``: also each firmware's file as that firmware applies it in flight on the
second log (:func:`benchmarks.bench_warmup_peers.flown_readings`, from
:mod:`calibration.firmware_flight`: PX4's 1-s poll and 1 °C publication gate, ArduPilot's
InvenSense 1-Hz low-pass, both run over the second log from its first sample): PX4's
script's file and soakcal's ``--format px4`` file through PX4's gate, ArduPilot's
tempcal's file and soakcal's ``--format ardupilot`` file through ArduPilot's filter.
Each soakcal file is compared with **the same firmware's** peer file, per sample and
flown (a PX4 user flies a PX4 file), with the same bootstrap and verdict
(:func:`flown_compare`).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_warmup_gen2 import verdict, wilson  # noqa: E402
from benchmarks.bench_warmup_peers import (  # noqa: E402
    MEAN_S,
    WarmupLog,
    five_s_means,
    flown_readings,
    heldout_rms_mg,
    imported_log,
    insample_rms_mg,
    method_ardupilot,
    method_export,
    method_px4,
    method_soakcal,
    rms_about_mean_mg,
    rows_1s,
    twin_log,
    xyz_mg,
)
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir  # noqa: E402
from benchmarks.blind.gen2.warmup import (  # noqa: E402
    WarmupCase,
    draw_case,
    import_args,
    simulate,
    write_log,
)
from calibration.model_file import load_model  # noqa: E402

WINDOW_S, DRAWS = 60.0, 2000
# the second log's profile: the same end temperature from a start 10 % of the rise higher,
# the time constant times a factor drawn from this range (a warmer day, another airflow)
START_SHIFT = 0.1
TAU_FACTOR = (0.7, 1.4)
NOISE_SEED_OFFSET = 500_000  # the second log's noise seed: the case's seed plus this
# the twin's second warm-up: τ 800 s instead of 600 s (a slower warm-up, inside the first
# log's span), another noise seed
TWIN_SECOND_TAU_S, TWIN_SEED = 800.0, 7
TWINS: dict[str, dict[str, float]] = {
    "twin": {},
    "twin + rate 40 µg/(°C/min)": {"rate_ug_per_c_per_min": 40.0},
    "twin + channel lag 60 s": {"channel_lag_s": 60.0},
    "twin + rate + lag": {"rate_ug_per_c_per_min": 40.0, "channel_lag_s": 60.0},
}


def second_case(case: WarmupCase) -> WarmupCase:
    """The same sensor's other warm-up: every truth field of ``case`` kept (sensor, bias
    polynomial and its reference, rate, hysteresis, drift, channel lag, offset, LSB and
    noise, rates, orientation), the profile changed: start ``START_SHIFT`` of the rise
    higher to the same end temperature, the time constant × a factor in ``TAU_FACTOR``
    drawn from the case's seed. Its noise is :func:`second_noise_seed`'s."""
    factor = float(np.random.default_rng([case.seed, 30]).uniform(*TAU_FACTOR))
    return replace(case, name=f"{case.name}b", start_c=case.start_c + START_SHIFT * case.span_c,
                   span_c=(1.0 - START_SHIFT) * case.span_c, tau_s=case.tau_s * factor)


def second_noise_seed(case: WarmupCase) -> int:
    return case.seed + NOISE_SEED_OFFSET


def whole_ratio_interval(t_s: np.ndarray, ours_g: np.ndarray, peers_g: tuple[np.ndarray, ...],
                         window_s: float = WINDOW_S, draws: int = DRAWS) -> list[list[float]]:
    """Per axis, a 95 % interval of RMS(ours) ÷ RMS(better peer) over every full 5-s mean
    of a log about their mean (:func:`benchmarks.bench_warmup_peers.insample_rms_mg`): a
    paired bootstrap over ``window_s`` windows of the means, each method's constant and
    the better peer taken again on each draw."""
    hs, per_method = five_s_means(t_s, (ours_g, *peers_g))
    means = np.stack(per_method)  # (methods, m, 3)
    window = (hs * MEAN_S // window_s).astype(int)
    groups = [np.flatnonzero(window == w) for w in np.unique(window)]
    rng = np.random.default_rng(0)
    ratios = []
    for _ in range(draws):
        pick = np.concatenate([groups[i] for i in rng.integers(0, len(groups), len(groups))])
        ms = means[:, pick].var(axis=1)  # (methods, 3): about the draw's own mean
        ratios.append(np.sqrt(ms[0] / np.min(ms[1:], axis=0)))
    lo, hi = np.percentile(np.asarray(ratios), [2.5, 97.5], axis=0)
    return [[float(a), float(b)] for a, b in zip(lo, hi, strict=True)]


def compare(first: WarmupLog, second: WarmupLog, true2_g: np.ndarray | None,
            work: Path, as_flown: bool = False) -> dict[str, object]:
    """Every method fitted on the whole ``first`` log, scored on the whole ``second``
    (module docstring); and the split's soakcal ÷ better peer on ``first``; with
    ``as_flown``, :func:`flown_compare` too."""
    n1 = first.t_s.size
    fit = np.zeros(n1 + second.t_s.size, bool)
    fit[:n1] = True
    # the peers fit the first log's samples and apply at the second's readings (they are
    # per-sample, so one joined log serves; ArduPilot's filter runs on the first log only)
    joined = WarmupLog(first.name, np.concatenate([first.t_s, second.t_s + first.t_s[-1] + 1e4]),
                       np.vstack([first.acc_g, second.acc_g]),
                       np.concatenate([first.temp_c, second.temp_c]))
    px4 = method_px4(joined, fit)[n1:]
    ardupilot = method_ardupilot(joined, fit)[0][n1:]
    res: dict[str, object] = {
        "minutes": [float(first.t_s[-1] / 60.0), float(second.t_s[-1] / 60.0)],
        "span_c": [[float(x.temp_c.min()), float(x.temp_c.max())] for x in (first, second)],
        "outside_share": float(np.mean((second.temp_c < first.temp_c.min())
                                       | (second.temp_c > first.temp_c.max()))),
    }
    methods: dict[str, np.ndarray | None] = {"none": second.acc_g, "px4": px4,
                                             "ardupilot": ardupilot}
    (work / "whole").mkdir(exist_ok=True)
    sc, res["soakcal_note"] = method_soakcal(first, work / "whole", np.ones(n1, bool), second)
    methods["soakcal"] = sc
    if sc is not None:
        model = work / "whole" / "model.json"
        res["rate_term"] = bool((json.loads(model.read_text()).get("temperature") or {})
                                .get("rate"))
        methods["export_px4"] = method_export(second, model)
        methods["export_ardupilot"] = method_export(second, model, firmware="ardupilot")
        # the PX4 header's FOLDED figure (file − model, stated from the first log) against
        # the file less the model on the second log
        fold = load_model(model).provenance.get("rate_fold") or {}
        res["stated_folded_mg"] = fold.get("rms_mg")
    ok = np.ones(second.t_s.size, bool) if sc is None else np.all(np.isfinite(sc), axis=1)
    sub = WarmupLog(second.name, second.t_s[ok], second.acc_g[ok], second.temp_c[ok])
    for key, comp in methods.items():
        res[key] = None if comp is None else insample_rms_mg(sub, comp[ok]).tolist()
        if true2_g is not None:
            res[f"{key}_truth"] = (None if comp is None else insample_rms_mg(
                sub, (true2_g - (second.acc_g - comp))[ok]).tolist())
        if key.startswith(("soakcal", "export")) and comp is not None:
            res[f"{key}_over_peer_95"] = whole_ratio_interval(
                sub.t_s, comp[ok], (px4[ok], ardupilot[ok]))
    if res.get("stated_folded_mg") is not None:
        res["file_vs_model_mg"] = insample_rms_mg(
            sub, (methods["export_px4"] - sc)[ok]).tolist()  # type: ignore[operator]
    if true2_g is not None:
        res["oracle"] = insample_rms_mg(sub, (second.acc_g - true2_g)[ok]).tolist()
    else:  # no truth: the floor is unknown, "within" is then "at or below the peer"
        res["oracle"] = [0.0, 0.0, 0.0]
    for key in ("soakcal", "export_px4", "export_ardupilot"):
        if key in methods:
            res[f"{key}_verdict"] = verdict({**res, "soakcal": res[key]})
    res["beyond"] = beyond_span(first, second, methods, ok, true2_g)
    if as_flown:
        res["flown"] = flown_compare(joined, fit, second, methods, ok, res["oracle"],
                                     work / "whole" / "model.json" if sc is not None else None)
    res["split"] = split_ratio(first, work)
    return res


def beyond_span(first: WarmupLog, second: WarmupLog, methods: dict[str, np.ndarray | None],
                ok: np.ndarray, true2_g: np.ndarray | None) -> dict[str, object] | None:
    """Where the second log goes beyond the first log's span, every method clamps, each at
    its own edge: soakcal at its fit rows' span (the 1-s rows' mean temperatures), PX4's
    and ArduPilot's scripts at their fit samples' extremes (the raw readings', noise and
    all; ArduPilot's after its 2-s average). The figure again (mg, per axis) on the 5-s
    means of the second log whose mean temperature lies inside soakcal's edges (about
    their own mean), beside the edges and the count of means outside; None when no 5-s
    mean lies outside."""
    rows = np.asarray(rows_1s(first, np.ones(first.t_s.size, bool)))
    lo_c, hi_c = float(rows[:, 1].min()), float(rows[:, 1].max())
    keys = [k for k in ("px4", "ardupilot", "soakcal") if methods.get(k) is not None]
    series = [second.temp_c[ok, None], *(methods[k][ok] for k in keys)]  # type: ignore[index]
    if true2_g is not None:
        series += [(true2_g - (second.acc_g - methods[k]))[ok] for k in keys]  # type: ignore[operator]
    _, means = five_s_means(second.t_s[ok], tuple(series))
    t_mean = means[0][:, 0]
    inside = (t_mean >= lo_c) & (t_mean <= hi_c)
    if inside.all():
        return None

    out: dict[str, object] = {
        "rows_edges_c": [lo_c, hi_c],
        "sample_edges_c": [float(first.temp_c.min()), float(first.temp_c.max())],
        "means_outside": int(np.sum(~inside)), "means": int(inside.size),
        "second_max_mean_c": float(t_mean.max()), "second_min_mean_c": float(t_mean.min())}
    for i, k in enumerate(keys):
        out[k] = rms_about_mean_mg(means[1 + i][inside]).tolist()
        if true2_g is not None:
            out[f"{k}_truth"] = rms_about_mean_mg(
                means[1 + len(keys) + i][inside]).tolist()
    return out


FIRMWARES = ("px4", "ardupilot")


def flown_compare(joined: WarmupLog, fit: np.ndarray, second: WarmupLog,
                  methods: dict[str, np.ndarray | None], ok: np.ndarray,
                  oracle: object, model: Path | None) -> dict[str, object]:
    """(``--as-flown``) each firmware's files on the second log, per sample and as that
    firmware flies them: the peer's file (PX4's script's, ArduPilot's tempcal's, fitted on
    the first log: ``joined``'s ``fit`` samples) and soakcal's exported file (``model``),
    each at the reading the firmware evaluates its offset at on the second log
    (:func:`benchmarks.bench_warmup_peers.flown_readings`). Per firmware and application:
    RMS of every full 5-s mean about their mean (mg), soakcal's file ÷ the same firmware's
    peer file with a 95 % paired bootstrap (:func:`whole_ratio_interval`), and the verdict
    against that peer (``bench_warmup_gen2.verdict``: won, within 10 % of the oracle, lost)."""
    at = flown_readings(second)
    n1 = joined.t_s.size - second.t_s.size
    first_c = joined.temp_c[:n1]
    peers = {"px4": method_px4(joined, fit, np.concatenate([first_c, at["px4"]]))[n1:],
             "ardupilot": method_ardupilot(joined, fit, np.concatenate(
                 [first_c, at["ardupilot"]]))[0][n1:]}
    sub = WarmupLog(second.name, second.t_s[ok], second.acc_g[ok], second.temp_c[ok])
    none = insample_rms_mg(sub, second.acc_g[ok]).tolist()
    out: dict[str, object] = {"px4_publications": int(np.unique(at["px4"]).size),
                              "ardupilot_lag_max_c": float(np.max(np.abs(
                                  at["ardupilot"] - second.temp_c)))}
    for fw in FIRMWARES:
        ours = {"per_sample": methods.get(f"export_{fw}"),
                "flown": None if model is None else method_export(
                    second, model, applied_at_c=at[fw], firmware=fw)}
        theirs = {"per_sample": methods[fw], "flown": peers[fw]}
        for how in ("per_sample", "flown"):
            peer_mg = insample_rms_mg(sub, theirs[how][ok]).tolist()  # type: ignore[index]
            key = f"{fw}_{how}"
            out[f"{key}_peer"] = peer_mg
            if ours[how] is None:
                out[key] = None
                continue
            comp = ours[how][ok]  # type: ignore[index]
            out[key] = insample_rms_mg(sub, comp).tolist()
            out[f"{key}_over_peer_95"] = whole_ratio_interval(
                sub.t_s, comp, (theirs[how][ok],))  # type: ignore[index]
            out[f"{key}_verdict"] = verdict({"none": none, "px4": peer_mg,
                                             "ardupilot": peer_mg, "oracle": oracle,
                                             "soakcal": out[key]})
    return out


def split_ratio(log: WarmupLog, work: Path) -> list[float] | None:
    """soakcal ÷ better peer on ``log``'s own alternate-block split (the other benches'
    figure), per axis; None when soakcal refuses."""
    (work / "split").mkdir(exist_ok=True)
    sc, _ = method_soakcal(log, work / "split")
    if sc is None:
        return None
    ok = np.all(np.isfinite(sc), axis=1)
    sub = WarmupLog(log.name, log.t_s[ok], log.acc_g[ok], log.temp_c[ok])
    ours = heldout_rms_mg(sub, sc[ok])
    peer = np.minimum(heldout_rms_mg(log, method_px4(log)),
                      heldout_rms_mg(log, method_ardupilot(log)[0]))
    return (ours / peer).tolist()


def run_gen2(seed: int, pools: object, work: Path, as_flown: bool = False
             ) -> dict[str, object]:
    case = draw_case(seed)
    case2 = second_case(case)
    base: dict[str, object] = {"case": case.name, "kinds": list(case.kinds),
                               "profile": case.profile,
                               "tau_factor": case2.tau_s / case.tau_s}
    logs, truths = [], []
    for c, noise in ((case, None), (case2, second_noise_seed(case))):
        data = simulate(c, pools, noise_seed=noise)  # type: ignore[arg-type]
        csv_path, _ = write_log(c, data, work)
        log, said = imported_log(csv_path, "csv", import_args(c), work)
        if log is None:
            return base | {"unusable": f"{c.name}: {said}"}
        logs.append(log)
        truths.append(data.true_g if data.t_s.size == log.t_s.size else None)
    return base | compare(logs[0], logs[1], truths[1], work, as_flown)


def run_twin(label: str, kw: dict[str, float], work: Path, as_flown: bool = False
             ) -> dict[str, object]:
    first = twin_log(label, seed=TWIN_SEED, **kw)  # type: ignore[arg-type]
    second = twin_log(label, seed=TWIN_SEED, tau_s=TWIN_SECOND_TAU_S,
                      noise_seed=TWIN_SEED + NOISE_SEED_OFFSET, **kw)  # type: ignore[arg-type]
    truth = twin_log(label, seed=TWIN_SEED, tau_s=TWIN_SECOND_TAU_S, noiseless=True,
                     **kw).acc_g  # type: ignore[arg-type]
    return {"case": label, "kinds": ["twin"], "profile": "heat_cool",
            "tau_factor": TWIN_SECOND_TAU_S / 600.0} | compare(first, second, truth, work,
                                                               as_flown)


# --- report ---------------------------------------------------------------------------------
VARIANTS = (("soakcal", "compensate"), ("export_px4", "PX4 file"),
            ("export_ardupilot", "ArduPilot file"))


def _f3(v: object) -> str:
    """x / y / z to the µg, as every table of this benchmark prints mg."""
    return xyz_mg(v, digits=3)


def _ratio_ci(r: dict[str, object], key: str, peer: object = None) -> str:
    """``r[key]`` ÷ ``peer`` per axis with its 95 % interval (``r[key + "_over_peer_95"]``);
    ``peer`` defaults to the better of the two scripts, ``min(r["px4"], r["ardupilot"])``."""
    if r.get(key) is None:
        return "refused"
    if peer is None:
        peer = np.minimum(r["px4"], r["ardupilot"])  # type: ignore[arg-type]
    ratio = np.asarray(r[key]) / np.asarray(peer)
    return " / ".join(f"{x:.2f} ({a:.2f}–{b:.2f})" for x, (a, b) in zip(
        ratio, r[f"{key}_over_peer_95"], strict=True))  # type: ignore[call-overload]


def case_table(results: list[dict[str, object]]) -> str:
    lines = ["| case | kinds | τ₂/τ₁ | outside % | better peer | soakcal | soakcal ÷ peer (95 %) "
             "| PX4 file ÷ peer (95 %) | ArduPilot file ÷ peer (95 %) | oracle | outcome "
             "(compensate / PX4 / ArduPilot) | split: soakcal ÷ peer |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        if "unusable" in r:
            lines.append(f"| {r['case']} | not compared: {r['unusable']} |"
                         + " |" * 10)
            continue
        peer = np.minimum(r["px4"], r["ardupilot"])  # type: ignore[arg-type]
        outs = " / ".join(str(r[f"{k}_verdict"]["outcome"])  # type: ignore[index]
                          if f"{k}_verdict" in r else "—" for k, _ in VARIANTS)
        lines.append(
            f"| {r['case']} | {', '.join(r['kinds'])} | {r['tau_factor']:.2f} | "  # type: ignore[arg-type]
            f"{100 * r['outside_share']:.0f} | {_f3(peer)} | {_f3(r['soakcal'])} | "  # type: ignore[operator]
            f"{_ratio_ci(r, 'soakcal')} | {_ratio_ci(r, 'export_px4')} | "
            f"{_ratio_ci(r, 'export_ardupilot')} | {_f3(r['oracle'])} | {outs} | "
            f"{_f3(r['split'])} |")
    return "\n".join(lines)


def summary(results: list[dict[str, object]], label: str) -> str:
    used = [r for r in results if "unusable" not in r]
    lines = [f"{label}: {len(results)} cases, {len(used)} compared",
             "", "| soakcal as | won | within 10 % of the oracle | lost | refused | axes: CI "
             "below 1 / straddles 1 / above 1 | ratio median, max |",
             "|---|---|---|---|---|---|---|"]
    for key, name in VARIANTS:
        outs = [str(r[f"{key}_verdict"]["outcome"]) if f"{key}_verdict" in r  # type: ignore[index]
                else "refused" for r in used]
        cis = [b for r in used if r.get(f"{key}_over_peer_95")
               for b in r[f"{key}_over_peer_95"]]  # type: ignore[union-attr]
        below = sum(hi < 1.0 for _, hi in cis)
        above = sum(lo > 1.0 for lo, _ in cis)
        ratios = [x for r in used if r.get(key) is not None for x in
                  np.asarray(r[key]) / np.minimum(r["px4"], r["ardupilot"])]  # type: ignore[arg-type]
        n = len(outs)
        won = outs.count("win")
        within = outs.count("win-within-floor")
        lo, hi = wilson(won + within, n)
        stats = (f"{np.median(ratios):.3f}, {np.max(ratios):.3f}" if ratios else "—")
        lines.append(f"| {name} | {won} | {within} (won or within {won + within}/{n}, 95 % "
                     f"{lo:.0%}–{hi:.0%}) | {outs.count('loss')} | "
                     f"{sum(o.startswith('refused') for o in outs)} | {below} / "
                     f"{len(cis) - below - above} / {above} | {stats} |")
    truth = [x for r in used if r.get("soakcal_truth") is not None for x in
             np.asarray(r["soakcal_truth"]) / np.minimum(r["px4_truth"], r["ardupilot_truth"])]  # type: ignore[arg-type]
    if truth:
        lines.append("")
        lines.append(f"Against the truth (compensate ÷ better peer, per axis): median "
                     f"{np.median(truth):.3f}, max {np.max(truth):.3f}, "
                     f"{sum(x <= 1.0 for x in truth)}/{len(truth)} axes at or below.")
    pairs = [(a, b) for r in used if r.get("split") and r.get("soakcal") is not None
             for a, b in zip(r["split"], np.asarray(r["soakcal"])  # type: ignore[arg-type]
                             / np.minimum(r["px4"], r["ardupilot"]), strict=True)]  # type: ignore[arg-type]
    if pairs:
        sp, sec = np.asarray(pairs).T
        lines.append("")
        lines.append(f"The split (alternate blocks of the first log) beside the second log, "
                     f"compensate ÷ better peer per axis: second ÷ split median "
                     f"{np.median(sec / sp):.3f} (range {np.min(sec / sp):.3f} … "
                     f"{np.max(sec / sp):.3f}); axes at or below 1 in the split and above "
                     f"in the second log: {int(np.sum((sp <= 1) & (sec > 1)))}, the reverse: "
                     f"{int(np.sum((sp > 1) & (sec <= 1)))}, of {sp.size}.")
    return "\n".join(lines)


def beyond_table(results: list[dict[str, object]]) -> str:
    """The cases whose second log goes beyond the first log's span (:func:`beyond_span`):
    compensate ÷ better peer over every 5-s mean and over those inside soakcal's edges."""
    lines = ["| case | 5-s means outside | soakcal's edges (1-s rows) | the peers' (PX4: samples) "
             "| second log's 5-s means reach | all means: compensate ÷ better peer | inside: "
             "better peer | inside: compensate | inside: ÷ better peer | inside, truth: "
             "compensate ÷ better peer |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        b = r.get("beyond")
        if not isinstance(b, dict) or r.get("soakcal") is None:
            continue
        peer = np.minimum(r["px4"], r["ardupilot"])  # type: ignore[arg-type]
        peer_in = np.minimum(b["px4"], b["ardupilot"])
        truth = (_f3(np.asarray(b["soakcal_truth"]) / np.minimum(b["px4_truth"],
                                                                 b["ardupilot_truth"]))
                 if "soakcal_truth" in b else "—")
        lines.append(
            f"| {r['case']} | {b['means_outside']} of {b['means']} | "
            f"{b['rows_edges_c'][0]:.3f} … {b['rows_edges_c'][1]:.3f} | "
            f"{b['sample_edges_c'][0]:.3f} … {b['sample_edges_c'][1]:.3f} | "
            f"{b['second_min_mean_c']:.3f} … {b['second_max_mean_c']:.3f} | "
            f"{_f3(np.asarray(r['soakcal']) / peer)} | {_f3(peer_in)} | {_f3(b['soakcal'])} | "
            f"{_f3(np.asarray(b['soakcal']) / peer_in)} | {truth} |")
    if len(lines) == 2:
        return "No 5-s mean of a second log lies beyond its first log's span."
    return "\n".join(lines)


def stated_table(results: list[dict[str, object]]) -> str:
    """The PX4 header's FOLDED figure (stated from the first log) against the file less
    the model on the second log, mg x / y / z (models with a folded rate term)."""
    lines = ["| case | stated FOLDED RMS (file − model) | second log: file − model |",
             "|---|---|---|"]
    lines += [f"| {r['case']} | {_f3(r['stated_folded_mg'])} | {_f3(r['file_vs_model_mg'])} |"
              for r in results if r.get("file_vs_model_mg") is not None]
    return "\n".join(lines)


FLOWN_NAMES = {"px4": "PX4", "ardupilot": "ArduPilot"}
HOW_NAMES = {"per_sample": "per sample", "flown": "flown"}


def flown_summary(results: list[dict[str, object]], label: str) -> str:
    """(``--as-flown``) per firmware, per sample and flown: soakcal's file against the same
    firmware's peer file, counted as :func:`summary` counts (won / within / lost)."""
    used = [r["flown"] for r in results if "flown" in r]
    lines = [f"{label}, each soakcal file ÷ the same firmware's peer file on the second log "
             f"({len(used)} cases)", "",
             "| file | applied | won | within 10 % of the oracle | lost | refused | axes: CI "
             "below 1 / straddles 1 / above 1 | ratio median, max |",
             "|---|---|---|---|---|---|---|---|"]
    for fw in FIRMWARES:
        for how in ("per_sample", "flown"):
            key = f"{fw}_{how}"
            outs = [str(f[f"{key}_verdict"]["outcome"]) if f.get(key) is not None  # type: ignore[index, union-attr]
                    else "refused" for f in used]
            cis = [b for f in used if f.get(key) is not None  # type: ignore[union-attr]
                   for b in f[f"{key}_over_peer_95"]]  # type: ignore[index]
            below = sum(hi < 1.0 for _, hi in cis)
            above = sum(lo > 1.0 for lo, _ in cis)
            ratios = [x for f in used if f.get(key) is not None  # type: ignore[union-attr]
                      for x in np.asarray(f[key]) / np.asarray(f[f"{key}_peer"])]  # type: ignore[index]
            won, within, n = outs.count("win"), outs.count("win-within-floor"), len(outs)
            lo, hi = wilson(won + within, n)
            stats = f"{np.median(ratios):.3f}, {np.max(ratios):.3f}" if ratios else "—"
            lines.append(f"| {FLOWN_NAMES[fw]} | {HOW_NAMES[how]} | {won} | {within} (won or "
                         f"within {won + within}/{n}, 95 % {lo:.0%}–{hi:.0%}) | "
                         f"{outs.count('loss')} | {outs.count('refused')} | {below} / "
                         f"{len(cis) - below - above} / {above} | {stats} |")
    return "\n".join(lines)


def flown_case_table(results: list[dict[str, object]]) -> str:
    """(``--as-flown``) per case, mg x / y / z: each firmware's peer file and soakcal's file,
    per sample and flown, and soakcal's ÷ the peer's as flown (95 %)."""
    lines = ["| case | PX4 script: per sample → flown | soakcal PX4 file: per sample → flown "
             "| ÷ PX4 script, flown (95 %) | ArduPilot tempcal: per sample → flown | soakcal "
             "ArduPilot file: per sample → flown | ÷ tempcal, flown (95 %) | outcome flown "
             "(PX4 / ArduPilot) |", "|---|---|---|---|---|---|---|---|"]
    for r in results:
        f = r.get("flown")
        if not isinstance(f, dict):
            continue
        outs = " / ".join(str(f[f"{fw}_flown_verdict"]["outcome"])  # type: ignore[index]
                          if f.get(f"{fw}_flown") is not None else "refused"
                          for fw in FIRMWARES)
        cells = []
        for fw in FIRMWARES:
            cells += [f"{_f3(f[f'{fw}_per_sample_peer'])} → {_f3(f[f'{fw}_flown_peer'])}",
                      f"{_f3(f.get(f'{fw}_per_sample'))} → {_f3(f.get(f'{fw}_flown'))}",
                      _ratio_ci(f, f"{fw}_flown", f.get(f"{fw}_flown_peer"))]
        lines.append(f"| {r['case']} | " + " | ".join(cells) + f" | {outs} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--realdata", help="the shared real recordings (noise pools)")
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--seed", type=int, default=1000, help="first gen2 case's seed")
    ap.add_argument("--only", help="comma-separated gen2 case seeds to run instead")
    ap.add_argument("--no-twin", action="store_true", help="skip the twin's four pairs")
    ap.add_argument("--as-flown", action="store_true",
                    help="also each firmware's file as the firmware flies it (module docstring)")
    ap.add_argument("--out", type=Path, help="write results.json and table.md here")
    args = ap.parse_args(argv)
    seeds = ([int(s) for s in args.only.split(",")] if args.only
             else list(range(args.seed, args.seed + args.cases)))
    pools = load_pools(realdata_dir(args.realdata)) if seeds else None
    gen2, twins = [], []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for s in seeds:
            gen2.append(run_gen2(s, pools, Path(tmp), args.as_flown))
            print(json.dumps(gen2[-1]), flush=True)
        if not args.no_twin:
            for label, kw in TWINS.items():
                twins.append(run_twin(label, kw, Path(tmp), args.as_flown))
                print(json.dumps(twins[-1]), flush=True)
    text = f"{len(seeds)} gen2 cases and {len(twins)} twin pairs in " \
           f"{time.perf_counter() - t0:.0f} s\n"
    for label, res in (("gen2", gen2), ("twin", twins)):
        if res:
            text += ("\n" + summary(res, label) + "\n\n" + case_table(res) + "\n\n"
                     + stated_table(res) + "\n\n" + beyond_table(res) + "\n")
            if args.as_flown:
                text += ("\n" + flown_summary(res, label) + "\n\n" + flown_case_table(res)
                         + "\n")
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "results.json").write_text(json.dumps(gen2 + twins, indent=1))
        (args.out / "table.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
