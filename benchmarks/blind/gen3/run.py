"""``python -m benchmarks.blind.gen3.run --n 300 --seed S --out OUT --jobs 1`` (issue 22):
generate gen3 nulls, run ``soakcal diagnose FILE --json`` on each in-process (the CLI entry,
so the gate applies as it does for a user), and write OUT/results.json and OUT/results.md.
Per-case lines go to OUT/cases.jsonl as they finish; a rerun skips the cases already there.
An alarm's CSV is kept under OUT/alarms/.

``--effect NAME [--size S]`` draws the same cases with one catalogue effect at S × its
detectable size (``gen3.effects``; default none: the nulls, draw for draw) and scores each
case (``gen3.score``: right, not established, wrong, missed) into OUT/results.md."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import shutil
import sys
import tempfile
import time
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.blind.gen3.case import (
    Case,
    channel_error_ug,
    draw_case,
    drawn_error_ug,
    simulate,
    stated_noise_ug,
)
from benchmarks.blind.gen3.effects import EFFECTS, draw_effect
from benchmarks.blind.gen3.report import write
from benchmarks.blind.gen3.score import classify
from benchmarks.blind.gen3.score import markdown as score_markdown
from benchmarks.blind.gen3.verdict import summarise
from benchmarks.blind.gen3.writer import write_csv


def case_seed(seed: int, index: int) -> int:
    """The case's own seed, from the run's seed and its index."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


def diagnose_json(path: Path) -> dict[str, Any]:
    """``soakcal diagnose PATH --json`` through the CLI entry, stdout captured."""
    from service.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["diagnose", str(path), "--json"])
    if code != 0:
        return {"mismatch": None, "verdict": f"exit {code}", "findings": []}
    return json.loads(buf.getvalue())


VARIANTS = ("none", "t-lsb-column", "t-dithered", "no-vibration", "gaussian-mean",
            "no-reseat")


def variant_case(case: Case, variant: str) -> Case:
    """``A+B``: both ablations."""
    for name in variant.split("+"):
        case = _one_variant(case, name)
    return case


def _one_variant(case: Case, variant: str) -> Case:
    """Ablations of one feature, everything else drawn the same: ``t-dithered`` raises the
    temperature channel's noise to at least 0.6 LSB per sample (its rounding averaged away;
    the other draws unchanged, so a case already dithered is the same recording);
    ``no-vibration``, ``gaussian-mean`` and ``no-reseat`` drop the vibration, the Student-t
    capture mean or the hand fixture's re-seating turns (the noise is then a new draw);
    ``t-lsb-column`` only writes ``sensor_lsb_c``."""
    if variant == "t-dithered":
        th = case.thermal
        noise = max(th.channel_noise_c, 0.6 * th.channel_lsb_c)
        return dataclasses.replace(case, thermal=dataclasses.replace(th, channel_noise_c=noise))
    if variant == "no-vibration":
        return dataclasses.replace(case, noise=dataclasses.replace(case.noise, vibration=None))
    if variant == "no-reseat":
        return dataclasses.replace(
            case, protocol=dataclasses.replace(case.protocol, place_max_rad=0.0))
    if variant == "gaussian-mean":
        return dataclasses.replace(case, noise=dataclasses.replace(case.noise, nu=None))
    return case


def run_case(task: tuple[Any, ...]) -> dict[str, Any]:
    index, seed, out, variant = task[:4]
    effect, size = (task[4], task[5]) if len(task) > 4 else ("none", 0.0)
    cs = case_seed(seed, index)
    case = variant_case(draw_case(cs), variant)
    if effect == "none":
        rows = simulate(case)
    else:
        drawn, info = draw_effect(effect, case, size)
        case = drawn.case
        if info.get("absorbed"):
            return {"index": index, "case_seed": cs, "variant": variant, "absorbed": True,
                    "effect": info, "features": case.features(), "mismatch": None,
                    "findings": [], "seconds": 0.0, "class": "absorbed"}
        rows = simulate(case, drawn)
    path = Path(out) / "cases" / f"gen3-{seed}-{index:04d}.csv"
    lsb = case.thermal.channel_lsb_c if "t-lsb-column" in variant.split("+") else None
    write_csv(rows, path, sensor_lsb_c=lsb)
    t0 = time.perf_counter()
    doc = diagnose_json(path)
    result = {"index": index, "case_seed": cs, "rows": len(rows), "variant": variant,
              "stated_noise_ug": round(stated_noise_ug(rows), 2),
              "drawn_error_ug": round(drawn_error_ug(rows), 2),
              "channel_error_ug": round(channel_error_ug(rows), 2),
              "features": case.features(), "seconds": round(time.perf_counter() - t0, 2),
              **summarise(doc)}
    if effect != "none":
        prot = doc.get("protocol") or {}
        result["effect"] = info
        result["not_separable"] = sorted({e for entry in prot.get("not_separable", [])
                                          for e in entry.get("effects", [])})
        result["position_order"] = prot.get("position_order")
        result["class"] = classify(effect, result)
    if result["mismatch"]:
        (Path(out) / "alarms").mkdir(exist_ok=True)
        shutil.copy(path, Path(out) / "alarms" / path.name)
    path.unlink()
    return result


def _done(jsonl: Path) -> dict[int, dict[str, Any]]:
    if not jsonl.exists():
        return {}
    out = {}
    for line in jsonl.read_text(encoding="utf-8").splitlines():
        if line.strip():
            r = json.loads(line)
            out[r["index"]] = r
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", required=True)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--variant", default="none",
                    help="one-feature ablations (variant_case), joined by '+': "
                    + ", ".join(VARIANTS))
    ap.add_argument("--only", default=None,
                    help="comma-separated case indices (e.g. a run's alarms) instead of all")
    ap.add_argument("--effect", default="none", choices=("none", *EFFECTS),
                    help="draw this catalogue effect into every case (gen3.effects)")
    ap.add_argument("--size", type=float, default=2.0,
                    help="the effect's amplitude in units of its detectable size")
    args = ap.parse_args(argv)
    if any(v not in VARIANTS for v in args.variant.split("+")):
        ap.error(f"--variant: each of {args.variant!r} must be one of {', '.join(VARIANTS)}")
    out = Path(args.out)
    (out / "cases").mkdir(parents=True, exist_ok=True)
    jsonl = out / "cases.jsonl"
    done = _done(jsonl)
    wanted = range(args.n) if args.only is None else [int(v) for v in args.only.split(",")]
    extra = () if args.effect == "none" else (args.effect, args.size)
    todo = [(i, args.seed, str(out), args.variant, *extra) for i in wanted if i not in done]
    with open(jsonl, "a", encoding="utf-8") as fh:
        if args.jobs > 1:
            with Pool(args.jobs) as pool:
                for r in pool.imap_unordered(run_case, todo):
                    _record(fh, r, done)
        else:
            for task in todo:
                _record(fh, run_case(task), done)
    if args.effect != "none":
        results = [done[i] for i in sorted(done) if i in set(wanted)]
        text = score_markdown(results)
        (out / "results.md").write_text(text, encoding="utf-8")
        print(text.split("\n\n")[0])
        return 0
    results = [_enriched(done[i], args.seed) for i in sorted(done) if i in set(wanted)]
    doc = write(out, results, {"title": f"seed {args.seed}, {len(results)} cases, "
                               f"variant {args.variant}", "seed": args.seed, "n": args.n,
                               "variant": args.variant})
    print(f"false alarms {doc['false_alarms']}/{doc['judged']} "
          f"(cannot judge {doc['cannot_judge']}); {out / 'results.md'}")
    return 0


def _enriched(r: dict[str, Any], seed: int) -> dict[str, Any]:
    """An alarm's or a refusal's line from before the error columns (and the gate's reason)
    were recorded, with them recomputed from its seed (the same draws)."""
    if r.get("mismatch") is False or ("channel_error_ug" in r and "reason" in r):
        return r
    rows = simulate(variant_case(draw_case(case_seed(seed, r["index"])),
                                 r.get("variant", "none")))
    out = {**r, "drawn_error_ug": round(drawn_error_ug(rows), 2),
           "channel_error_ug": round(channel_error_ug(rows), 2)}
    if r.get("mismatch") is None and "reason" not in r:  # a refusal: ask the gate again
        path = Path(tempfile.mkdtemp()) / "case.csv"
        write_csv(rows, path)
        out["reason"] = diagnose_json(path).get("reason")
        shutil.rmtree(path.parent)
    return out


def _record(fh: Any, r: dict[str, Any], done: dict[int, dict[str, Any]]) -> None:
    fh.write(json.dumps(r, default=str) + "\n")
    fh.flush()
    done[r["index"]] = r
    flag = "ALARM " + ",".join(f["effect"] for f in r["findings"]) if r["mismatch"] else "ok"
    if "class" in r:
        flag = f"{r['class']}: {flag}"
    print(f"[{r['index']}] {r['seconds']} s {flag}", file=sys.stderr, flush=True)


if __name__ == "__main__":
    sys.exit(main())
