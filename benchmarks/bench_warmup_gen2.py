"""One-orientation warm-ups from the second generator: soakcal beside PX4 and ArduPilot.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.bench_warmup_gen2 \\
        --realdata DIR [--cases 40] [--seed 1000] [--out DIR] [--keep DIR] [--coarse-dither]

Each case is drawn by :func:`benchmarks.blind.gen2.warmup.draw_case` (seed ``--seed + i``):
a thermal profile, a sensor, a temperature channel and noise, written as the CSV a
flight controller's log export would be and read back through ``soakcal import --format
csv`` (:func:`benchmarks.bench_warmup_peers.imported_log`), then scored exactly as
``bench_warmup_peers`` scores a ``--log`` (:func:`benchmarks.bench_warmup_peers.evaluate`:
10-s blocks alternately fit and held out, RMS of the held-out 5-s means, mg per axis).

Per case: the ratio soakcal / the better of PX4's and ArduPilot's method, per axis; a
case is **won** when soakcal is at or below the better peer on all three axes, **won
within the floor** when on every axis it is at or below the better peer plus 10 % of the
noise floor (the difference is then not measurable on this log). The floor here is the
**oracle**: the log's noise alone (the logged samples less the generator's true output)
scored the same way, what a perfect compensation would score; ``bench_warmup_peers``'
own ``floor`` (two 5-s means of a held-out block, ÷ √2) is in the results too, but on
these logs it also holds the uncompensated change of the bias over 5 s (a fast warm-up
moves a 1 mg/°C part by a tenth of a mg in 5 s), so it reads high. A refusal (exit 2) is a
**loss** when a peer compensates the log (the better peer halves the uncompensated
error on some axis where it is at least twice the floor), otherwise *neutral* (nothing
compensates it). Win rates come with a 95 % Wilson interval.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.bench_warmup_peers import (  # noqa: E402
    WarmupLog,
    evaluate,
    heldout_rms_mg,
    imported_log,
    method_export,
    stated_table,
    xyz_mg,
)
from benchmarks.blind.gen2.realnoise import NoisePools, load_pools, realdata_dir  # noqa: E402
from benchmarks.blind.gen2.warmup import (  # noqa: E402
    WarmupCase,
    draw_case,
    import_args,
    simulate,
    write_log,
)

FLOOR_TOLERANCE = 0.10  # "within the floor": at most this fraction of the floor worse


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion k/n."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def verdict(res: dict[str, object]) -> dict[str, object]:
    """The case's ratios and outcome (module docstring)."""
    none, px4, ap, floor = (np.asarray(res[k], float) for k in ("none", "px4", "ardupilot",
                                                                 "oracle"))
    peer = np.minimum(px4, ap)
    out: dict[str, object] = {"better_peer": peer.tolist()}
    if res["soakcal"] is None:
        compensable = bool(np.any((peer <= 0.5 * none) & (none >= 2 * floor)))
        out.update(outcome="refused-loss" if compensable else "refused-neutral", ratio=None)
        return out
    sc = np.asarray(res["soakcal"], float)
    ratio = sc / peer
    out["ratio"] = ratio.tolist()
    out["worst_ratio"] = float(ratio.max())
    if np.all(sc <= peer):
        out["outcome"] = "win"
    elif np.all(sc <= peer + FLOOR_TOLERANCE * floor):
        out["outcome"] = "win-within-floor"
    else:
        out["outcome"] = "loss"
    return out


def run_case(case: WarmupCase, pools: NoisePools, workdir: Path, keep: Path | None,
             export: bool = False) -> dict[str, object]:
    data = simulate(case, pools)
    csv_path, truth_path = write_log(case, data, keep or workdir)
    log, said = imported_log(csv_path, "csv", import_args(case), workdir)
    base: dict[str, object] = {"case": case.name, "seed": case.seed, "kinds": list(case.kinds),
                               "profile": case.profile, "minutes": case.duration_s / 60.0,
                               "out_hz": case.out_hz, "lag_s": case.channel_lag_s,
                               "lsb_c": case.channel_lsb_c, "order": case.bias_order,
                               "channel_noise_c": case.channel_noise_c,
                               "true_change_mg": (np.ptp(data.true_g, 0) * 1e3).tolist()}
    if log is None:
        return base | {"unusable": said, "outcome": "not-compared"}
    res = evaluate(log, workdir, export=export)
    res["log"] = case.name
    if export and "export" in res and data.t_s.size == log.t_s.size:
        # the exported file against the generator's truth, held out
        offset = log.acc_g - method_export(log, workdir / "model.json")
        truth = WarmupLog(case.name, log.t_s, data.true_g - offset, log.temp_c)
        res["file_vs_truth_heldout_mg"] = heldout_rms_mg(truth, truth.acc_g).tolist()
    # the oracle: the noise alone (the log less its true output) scored the same way
    noise = WarmupLog(case.name, data.t_s, data.acc_g - data.true_g, data.temp_c)
    res["oracle"] = heldout_rms_mg(noise, noise.acc_g).tolist()
    return base | res | verdict(res)


def summary(results: list[dict[str, object]]) -> str:
    scored = [r for r in results if r["outcome"] not in ("not-compared", "refused-neutral")]
    n = len(scored)
    lines = [f"{len(results)} cases; {n} scored (a neutral refusal or an import refusal is "
             "not scored)"]
    for label, ok in (("won (≤ better peer on every axis)", ("win",)),
                      ("won within 10 % of the floor", ("win", "win-within-floor"))):
        k = sum(r["outcome"] in ok for r in scored)
        lo, hi = wilson(k, n)
        lines.append(f"- {label}: {k}/{n} = {k / max(n, 1):.0%} (95 % {lo:.0%} … {hi:.0%})")
    axes = [x for r in scored if r.get("ratio") for x in r["ratio"]]  # type: ignore[union-attr]
    if axes:
        a = np.asarray(axes)
        k = int(np.sum(a <= 1.0))
        lo, hi = wilson(k, a.size)
        lines.append(f"- axes at or below the better peer: {k}/{a.size} = {k / a.size:.0%} "
                     f"(95 % {lo:.0%} … {hi:.0%}); ratio median {np.median(a):.3f}, "
                     f"90th percentile {np.percentile(a, 90):.3f}, max {a.max():.3f}")
    ref = [r for r in results if str(r["outcome"]).startswith("refused")]
    lines.append(f"- refusals: {len(ref)} ({sum(r['outcome'] == 'refused-loss' for r in ref)} "
                 "of logs a peer compensates)")
    by_kind: dict[str, list[str]] = defaultdict(list)
    for r in scored:
        for k_ in r["kinds"]:  # type: ignore[union-attr]
            by_kind[k_].append(str(r["outcome"]))
    lines.append("")
    lines.append("| kind | cases | won | within floor | lost | refused (loss) |")
    lines.append("|---|---|---|---|---|---|")
    for k_, outs in sorted(by_kind.items()):
        lines.append(f"| {k_} | {len(outs)} | {outs.count('win')} | "
                     f"{outs.count('win-within-floor')} | {outs.count('loss')} | "
                     f"{outs.count('refused-loss')} |")
    return "\n".join(lines)


def case_table(results: list[dict[str, object]]) -> str:
    def f3(v: object) -> str:
        return xyz_mg(v, digits=3)

    lines = ["| case | kinds | min | better peer | soakcal | ratio | oracle | outcome |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results:
        if r["outcome"] == "not-compared":
            lines.append(f"| {r['case']} | {', '.join(r['kinds'])} | {r['minutes']:.0f} | "  # type: ignore[arg-type]
                         f"not compared: {r['unusable']} | | | | |")
            continue
        sc = r["soakcal"]
        lines.append(f"| {r['case']} | {', '.join(r['kinds'])} | {r['minutes']:.0f} | "  # type: ignore[arg-type]
                     f"{f3(r['better_peer'])} | "
                     f"{'refused: ' + str(r['soakcal_note']) if sc is None else f3(sc)} | "
                     f"{f3(r.get('ratio'))} | {f3(r['oracle'])} | {r['outcome']} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--realdata", help="the shared real recordings (noise pools)")
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--seed", type=int, default=1000, help="first case's seed")
    ap.add_argument("--only", help="comma-separated case seeds to run instead")
    ap.add_argument("--out", type=Path, help="write results.json and table.md here")
    ap.add_argument("--keep", type=Path, help="keep the generated CSV and truth files here")
    ap.add_argument("--coarse-dither", action="store_true",
                    help="each case with a 1 °C channel dithered by 0.1-0.6 LSB of noise "
                         "(draw_case(seed, coarse_dither=True))")
    ap.add_argument("--export", action="store_true",
                    help="also the PX4 file soakcal exports: its header's stated RMS (file − "
                         "model) against the measured, and the file against the truth")
    args = ap.parse_args(argv)
    pools = load_pools(realdata_dir(args.realdata))
    seeds = ([int(s) for s in args.only.split(",")] if args.only
             else list(range(args.seed, args.seed + args.cases)))
    results = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for s in seeds:
            r = run_case(draw_case(s, args.coarse_dither), pools, Path(tmp), args.keep,
                         args.export)
            results.append(r)
            print(json.dumps(r), flush=True)
    text = (f"{len(seeds)} cases in {time.perf_counter() - t0:.0f} s\n\n" + summary(results)
            + "\n\n" + case_table(results))
    if args.export:
        text += ("\n\nThe stated RMS (file − model) against the measured (--export):\n\n"
                 + stated_table(results))
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "results.json").write_text(json.dumps(results, indent=1))
        (args.out / "table.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
