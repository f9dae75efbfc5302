"""The gen3 results as JSON and markdown (issue 22): false alarms with Clopper–Pearson 95 %
intervals, broken down by noise feature and protocol, and every alarm's findings."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks.blind.gen3.stats import clopper_pearson, rate_text


def _dither(f: dict[str, Any]) -> float:
    """The temperature channel's noise per sample over its LSB."""
    return float(f.get("t_dither", f["t_noise_c"] / f["t_lsb_c"]))


def _n_bucket(n: int) -> str:
    return "20–99" if n < 100 else "100–199" if n < 200 else "200–400"


BREAKDOWNS: dict[str, Callable[[dict[str, Any]], str]] = {
    "heavy-tailed capture mean (t, ν 4–10)": lambda f: "yes" if f["heavy_nu"] else "no",
    "slow vibration": lambda f: "yes" if f["vibration_rms_mg"] else "no",
    "raw quantisation": lambda f: "none" if f["raw_lsb_ug"] is None
    else f"{f['raw_lsb_ug']:g} µg",
    "fixture (hand = re-seated ≤ 0.5 mrad)": lambda f: f["fixture"],
    "temperature channel LSB (°C)": lambda f: f"{f['t_lsb_c']:g}",
    "temperature channel noise / LSB (< 0.5: rounding not dithered away)":
    lambda f: "< 0.3" if _dither(f) < 0.3 else "0.3–0.5" if _dither(f) < 0.5 else "≥ 0.5",
    "schedule": lambda f: f["schedule"],
    "plateau order": lambda f: f["order"],
    "visits": lambda f: str(f["visits"]),
    "position order": lambda f: "shuffled" if f["shuffled"] else "schedule",
    "samples per capture": lambda f: _n_bucket(f["n"]),
    "plateaus": lambda f: "4–6" if f["plateaus"] <= 6 else "7–11",
}


def _judged(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in results if r.get("mismatch") is not None]


def breakdown(results: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for name, key in BREAKDOWNS.items():
        groups: dict[str, list[bool]] = {}
        for r in _judged(results):
            groups.setdefault(key(r["features"]), []).append(bool(r["mismatch"]))
        out[name] = {}
        for g, flags in sorted(groups.items()):
            k, n = sum(flags), len(flags)
            lo, hi = clopper_pearson(k, n)
            out[name][g] = {"alarms": k, "n": n, "rate": k / n, "ci95": [lo, hi]}
    return out


def alarms(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in results if r.get("mismatch")]


def summary(results: list[dict[str, Any]], meta: dict[str, Any]) -> dict[str, Any]:
    judged = _judged(results)
    k, n = len(alarms(results)), len(judged)
    lo, hi = clopper_pearson(k, n)
    return {"meta": meta, "cases": len(results), "judged": n,
            "cannot_judge": len(results) - n, "false_alarms": k,
            "rate": k / n if n else None, "ci95": [lo, hi],
            "breakdown": breakdown(results), "alarms": alarms(results),
            "refused": [r for r in results if r.get("mismatch") is None]}


def _features_text(f: dict[str, Any]) -> str:
    bits = [f"{f['schedule']}×{f['visits']}", f"{f['plateaus']} pl {f['order']}",
            f"n={f['n']}@{f['odr_hz']:g}Hz", f"T LSB {f['t_lsb_c']:g} (noise/LSB {_dither(f):.2f})"]
    if f["heavy_nu"]:
        bits.append(f"t ν={f['heavy_nu']}")
    if f["vibration_rms_mg"]:
        bits.append(f"vib {f['vibration_rms_mg']} mg")
    if f["raw_lsb_ug"]:
        bits.append(f"LSB {f['raw_lsb_ug']:g} µg")
    if f["fixture"] == "hand":
        bits.append(f"hand ≤{f['place_max_mrad']} mrad")
    return ", ".join(bits)


def _case(r: dict[str, Any]) -> str:
    """seed/index (the run's seed where the report spans several runs)."""
    return f"{r['seed']}/{r['index']}" if "seed" in r else str(r["index"])


def _p(v: Any) -> str:
    return "–" if v is None else f"{float(v):.2g}"


def markdown(doc: dict[str, Any]) -> str:
    lines = [f"# gen3 nulls: {doc['meta'].get('title', '')}", "",
             f"False alarms (mismatch true): {rate_text(doc['false_alarms'], doc['judged'])}"
             f" (Clopper–Pearson 95 %); cannot judge: {doc['cannot_judge']}.", "",
             "## Alarms", "",
             "| case | case seed | features | effect (test, p_family) | baseline / noise µg "
             "| T-channel error µg |", "|---|---|---|---|---|---|"]
    for r in doc["alarms"]:
        fx = "; ".join(f"{f['effect']} ({f['test']}, {_p(f['p_family'] or f['p_value'])})"
                       for f in r["findings"]) or "(no finding)"
        if r.get("scan_significant"):
            fx += f"; scan p={_p(r.get('scan_p'))}"
        lines.append(f"| {_case(r)} | {r['case_seed']} | {_features_text(r['features'])} | "
                     f"{fx} | {r['baseline_rmse_ug']} / {r['baseline_noise_ug']} | "
                     f"{r.get('channel_error_ug', '–')} |")
    lines += ["", "## Cannot judge (the gate's reason, first words)", "",
              "| case | schedule | reason |", "|---|---|---|"]
    for r in doc["refused"]:
        lines.append(f"| {_case(r)} | {r['features']['schedule']} | "
                     f"{(r.get('reason') or r.get('verdict') or '')[:90]} |")
    for name, groups in doc["breakdown"].items():
        lines += ["", f"## By {name}", "", "| value | false alarms | 95 % |", "|---|---|---|"]
        for g, s in groups.items():
            lines.append(f"| {g} | {s['alarms']}/{s['n']} = {100 * s['rate']:.1f} % | "
                         f"{100 * s['ci95'][0]:.1f}–{100 * s['ci95'][1]:.1f} % |")
    return "\n".join(lines) + "\n"


def write(out: Path, results: list[dict[str, Any]], meta: dict[str, Any]) -> dict[str, Any]:
    doc = summary(results, meta)
    (out / "results.json").write_text(json.dumps(doc, indent=1, default=str), encoding="utf-8")
    (out / "results.md").write_text(markdown(doc), encoding="utf-8")
    return doc
