"""Input-only names against a settling at each slot of the visiting order (issue 22).

    python -m benchmarks.blind.gen2.slot_confound --realdata DIR --out OUT [--results STEM]

For every case of an earlier ``gen2.run`` (``OUT/cases``, ``OUT/keys``,
``OUT/diagnoses.json``) whose diagnosis gives a finding an input-only name (a function of
the specific force alone: ``cross_coupling``, ``scale_nonlinearity``), and for every
catalogue case whose key is such an effect, asks whether a settling after each move that
repeats at each slot of the visiting order (a free per-axis offset per slot,
``protocol_order.slot_offset_columns``, the oracle's rival ``separable.SLOT``) takes the
named term's signature:

* ``repeated``: every plateau visits the positions in the same order
  (``time_and_position_confounded``, the reason ``turntable_geometry`` is withheld);
* ``dof_off_slot``: the rank of the named term's whitened columns after the base model and
  the slot columns (0: the slots span the term whatever its coefficients);
* for a catalogue key, the oracle's λ and power of the true effect's own columns against
  the base alone and against base + slots (``separable.separability``).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir
from benchmarks.blind.gen2.separable import SLOT, Oracle, emit, separability, true_signal_g
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.level import ALPHA
from calibration.discrepancy.protocol_order import (
    slot_offset_columns,
    time_and_position_confounded,
)

INPUT_ONLY = tuple(k for k, e in BY_ID.items() if e.input_only)


def named_input_only(d: dict) -> list[str]:
    """Input-only effects a finding of diagnosis ``d`` names (its ``effect``)."""
    return list(dict.fromkeys(f.get("effect") for f in d.get("findings") or []
                              if f.get("effect") in INPUT_ONLY))


def dof_off_slot(o: Oracle, eid: str) -> int:
    """Rank of effect ``eid``'s whitened columns after the base and the slot columns."""
    ctx = o.ctx
    U = o.basis([o.w(slot_offset_columns(ctx.steps, ctx.positions, ctx.t_s))])
    eff = BY_ID[eid]
    X = np.hstack([o.w(eff.regressors(ctx, th)) for th in eff.grid(ctx)])
    Xo = o.off(U, X)
    scale = max(float(np.linalg.norm(X)), 1e-300)
    s = np.linalg.svd(Xo, compute_uv=False)
    return int(np.sum(s > 1e-6 * scale))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--alpha", type=float, default=ALPHA)
    ap.add_argument("--results", type=Path, default=None)
    a = ap.parse_args(argv)
    pools = load_pools(realdata_dir(a.realdata))
    dpath = a.out / "diagnoses.json"
    diags = json.loads(dpath.read_text()) if dpath.is_file() else {}
    rows = []
    for kp in sorted((a.out / "keys").glob("*.json")):
        c, k = kp.stem, json.loads(kp.read_text())
        named = named_input_only(diags.get(c, {}))
        key_io = k["kind"] == "catalogue" and BY_ID.get(k.get("catalogue_id"),
                                                        None) is not None and BY_ID[
            k["catalogue_id"]].input_only
        if not named and not key_io:
            continue
        csv = a.out / "cases" / f"{c}.csv"
        if not csv.is_file():
            continue
        o = Oracle(csv)
        ctx = o.ctx
        row = {"case": c, "kind": k["kind"], "effect": k.get("effect"),
               "multiple": k.get("multiple"), "protocol": k.get("protocol"),
               "repeated": bool(time_and_position_confounded(ctx.steps, ctx.positions,
                                                             ctx.t_s)),
               "named": named, "top": ((diags.get(c, {}).get("findings") or [{}])[0]
                                       .get("effect")),
               "dof_off_slot": {e: dof_off_slot(o, e) for e in
                                dict.fromkeys(named + ([k["catalogue_id"]] if key_io
                                                       else []))}}
        if key_io:
            s_g, _ = true_signal_g(k, pools)
            sep = separability(o, k, s_g, [SLOT], a.alpha / 2)
            row["oracle"] = {n: {x: sep[n][x] for x in ("lam_cols", "dof", "power_cols",
                                                         "lam_known")}
                             for n in ("base", SLOT)}
        rows.append(row)
        print(_line(row), file=sys.stderr)
    return emit(markdown(rows), rows, a.results)


def _line(r: dict) -> str:
    orc = r.get("oracle")
    tail = (f" base λ={orc['base']['lam_cols']:.1f}/{orc['base']['dof']} | slot "
            f"λ={orc[SLOT]['lam_cols']:.2f}/{orc[SLOT]['dof']} "
            f"p={orc[SLOT]['power_cols']:.2f} known λ={orc[SLOT]['lam_known']:.2f}"
            if orc else "")
    return (f"{r['case']} {r['kind'][:9]:9s} {str(r['effect'])[:18]:18s} ×{r['multiple']} "
            f"{str(r['protocol'])[:40]:40s} rep={int(r['repeated'])} named={r['named']} "
            f"top={r['top']} off-slot dof={r['dof_off_slot']}{tail}")


def markdown(rows: list[dict]) -> str:
    """Per kind and named effect: names on a repeated order, and how many the slots span."""
    by: dict[tuple, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for r in rows:
        for e in r["named"]:
            g = by[(r["kind"], r["effect"] if r["kind"] == "catalogue" else "-", e)]
            g["named"] += 1
            g["repeated"] += r["repeated"]
            g["spanned"] += r["repeated"] and r["dof_off_slot"][e] == 0
            g["top"] += r["top"] == e
            g["top_repeated"] += r["top"] == e and r["repeated"]
    out = ["| kind | key | named | findings naming it | on a repeated order | of which "
           "the slots span (0 dof left) | top finding | top, repeated order |",
           "|---|---|---|---|---|---|---|---|"]
    for (kind, key, e), g in sorted(by.items()):
        out.append(f"| {kind} | {key} | {e} | {g['named']} | {g['repeated']} | "
                   f"{g['spanned']} | {g['top']} | {g['top_repeated']} |")
    cat = [r for r in rows if "oracle" in r and r["multiple"] == 2.0]
    if cat:
        out += ["", "| catalogue key at 2× | n | repeated order | oracle power vs base "
                "(median) | oracle λ vs base + slots, repeated (max) | power vs base + "
                "slots, repeated (max) | power vs base + slots, varied (median) |",
                "|---|---|---|---|---|---|---|"]
        for e in sorted({r["effect"] for r in cat}):
            rs = [r for r in cat if r["effect"] == e]
            rep = [r for r in rs if r["repeated"]]
            var = [r for r in rs if not r["repeated"]]
            out.append(
                f"| {e} | {len(rs)} | {len(rep)} | "
                f"{np.median([r['oracle']['base']['power_cols'] for r in rs]):.2f} | "
                + (f"{max(r['oracle'][SLOT]['lam_cols'] for r in rep):.2g} | "
                   f"{max(r['oracle'][SLOT]['power_cols'] for r in rep):.2g}" if rep
                   else "– | –") + " | "
                + (f"{np.median([r['oracle'][SLOT]['power_cols'] for r in var]):.2f}"
                   if var else "–") + " |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
