"""Oracle separability of the third generator's catalogue cases (issue 22).

    python -m benchmarks.blind.gen3.separable OUT1 OUT2 … [--results STEM]

A scorer, not part of the generator: it imports the diagnosis (gen2's oracle,
``benchmarks.blind.gen2.separable``), the generator modules never do. For each case of a
``gen3.run --effect NAME`` run (``OUT/cases.jsonl``) it draws the case again from its seed
(the same draws: ``case_seed``, ``variant_case``, ``effects.draw_effect``, ``simulate``),
writes its recording (checked against the kept ``OUT/alarms`` CSV when there is one) and
asks, in the diagnosis' own whitened residual space (gen2's ``Oracle``: ``build_problem``,
``robust_scale``) with the temperature channel's per-plateau rounding added as a random
effect along ∂output/∂T (``ChannelOracle``: gen3's size rule counts it, the diagnosis'
whitening does not): could the data have told the drawn effect from the base model and
from the rival(s) the diagnosis named beside it, at this size? (A hand fixture's re-seating
turns are not added: ``markdown`` reports the table fixture's cases apart.)

* the signature (``signature_g``): what the effect put into the recording, noise-free —
  the rows' ``extra_g`` (``amplitude × pattern``; an outlier's per-row amplitudes ×
  directions), and for ``temperature_sensor``, which changes no output, what the base
  model, fitted on the stepped channel, cannot follow: the output at the die temperature
  minus the output at the die temperature plus the channel's step (gen2's
  ``true_signal_g``);
* the check: the recording less its noise-free output (the sensor at the die temperature
  plus the signature: ``err_g``, the drawn noise), whitened and off the base, has rms ≈ 1
  when the oracle's noise units are this recording's;
* the rivals (``named_rivals``): the other candidates of each ``not_identifiable``
  finding (beside the effect, or, where the effect is not among them, what the diagnosis
  put forward for the structure instead: ``kid_named`` tells the two apart); the ids in
  the effect's "not separable from X here" entry of ``not_identifiable``; a term withheld
  at a place for too few input levels (any function of those levels); and each
  ``protocol.not_separable`` entry holding the effect — its members the effect cannot be
  told from (``Confusion.alternatives``), its outside rival
  (a jump of the output where the temperature crosses a T*, at the T* that fits the
  signature best) and, where the positions are visited in the same order on every plateau,
  a free offset per visiting slot;
* gen2's ``separability`` then gives λ and the power in the effect's own catalogue columns
  after base and rivals, at α/2 of the diagnosis' family test; gen2's ``classify`` makes a
  "not established" answer *honest* when that power (all rivals at once, as gen2) is
  below one half, a *power deficit* otherwise (the power against the rival most like the
  effect, one at a time, is reported beside it). A "missed" case is *detectable* when the
  power against the base alone is at least one half — one test of the effect's own
  columns at α/2, not the diagnosis' family test over every candidate: an upper bound.
  ``base_absorbs``: gen3's share of the pattern left after the base is below
  1 − ``absorbed_max``, where the diagnosis withholds the term as absorbed.

"right among oracle-separable" = right / (right + deficit + wrong + missed detectable).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import tempfile
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats as sps
from scipy.optimize import brentq

from benchmarks.blind.gen2.separable import (
    LEVELS,
    POWER_SEPARABLE,
    SLOT,
    Oracle,
    chi2_power,
    rival_columns,
    separability,
)
from benchmarks.blind.gen2.separable import classify as oracle_class
from benchmarks.blind.gen3.case import draw_case, simulate
from benchmarks.blind.gen3.effects import channel_noise, draw_effect
from benchmarks.blind.gen3.run import diagnose_json, variant_case
from benchmarks.blind.gen3.score import classify as score_class
from benchmarks.blind.gen3.stats import clopper_pearson
from benchmarks.blind.gen3.writer import write_csv
from calibration.discrepancy import stats
from calibration.discrepancy.effects import ALL_EFFECTS, BY_ID
from calibration.discrepancy.level import ALPHA
from calibration.discrepancy.protocol import Confusion
from calibration.discrepancy.protocol_order import time_and_position_confounded
from calibration.discrepancy.slot_settling import SLOT_SETTLING
from calibration.discrepancy.temperature_jump import thresholds_c

JUMP = "a jump of the output where the temperature crosses"
SAME_ORDER = "same order on every plateau"


def family_multiplicity(ctx: Any, kid: str) -> tuple[int, int]:
    """(K, G): the catalogue families the diagnosis can test on this recording
    (``identifiable``), and the drawn effect's own multiplicity within its family (its grid
    values; a per-reading effect: the readings). The family test's level for the effect is
    then at most α/2 / (K·G) (Bonferroni over the families of its min-P, Šidák over the
    grid within): a lower bound on its power, where the oracle's one test of the effect's
    own columns at α/2 is an upper bound."""
    k = sum(1 for e in ALL_EFFECTS if e.identifiable(ctx)[0])
    eff = BY_ID[kid]
    g = int(ctx.n) if eff.per_reading else max(len(eff.grid(ctx)), 1)
    return max(k, 1), g


def tail_power(lam: float, dof: int, level: float, readings: int, nu: float) -> float:
    """Power of one reading's test (``dof`` columns, noncentrality ``lam``) at ``level``
    spread over ``readings`` (Bonferroni, as gen2's oracle), its threshold read from the
    per-reading law the noise has: the Student-t mixture at ν (``stats.reading_logsf``,
    the law diagnose's outlier null uses) where gen3 drew Student-t capture means, χ²
    otherwise. The alternative is taken as the noncentral χ² about that threshold (the
    shift dominates the reading's noise at these sizes). Why: gen3 sizes an outlier from
    the Gaussian σ of a mean; with means drawn from t_ν a reading that far off is a
    chance event among a few hundred, and a χ² threshold called such a miss detectable."""
    if dof <= 0:
        return 0.0
    if not np.isfinite(nu):
        return chi2_power(lam, dof, level / max(readings, 1))
    target = float(np.log(level / max(readings, 1)))
    hi = 1.0
    while float(stats.reading_logsf(hi, dof, nu)) > target:
        hi *= 2.0
    t_star = brentq(lambda t: float(stats.reading_logsf(t, dof, nu)) - target, 0.0, hi)
    return float(sps.ncx2.sf(t_star, dof, max(lam, 1e-12)))


class ChannelOracle(Oracle):
    """gen2's ``Oracle`` with the temperature channel's per-plateau rounding as a random
    effect: the diagnosis' whitening does not carry it, gen3's size rule does
    (``effects.noncentrality``: u_j ~ N(0, ``plateau_var``) per plateau j along
    ∂output/∂T). In the oracle's noise units the covariance is I + pv·GGᵀ (G: the whitened
    per-plateau ∂output/∂T columns); ``w`` applies (I + pv·GGᵀ)^(−1/2) after the
    diagnosis' whitening and the base is re-projected in that metric, so λ and power are
    generalised least squares against the drawn channel as well."""

    def __init__(self, csv: Path, slope_g_per_c: np.ndarray, steps: np.ndarray,
                 plateau_var: float) -> None:
        super().__init__(csv)
        self._q: np.ndarray | None = None
        if plateau_var > 0.0:
            cols = np.concatenate([(slope_g_per_c * (steps == k)[:, None])[:, :, None]
                                   for k in np.unique(steps)], axis=2)
            G = Oracle.w(self, cols) * np.sqrt(plateau_var)
            q, sv, _ = np.linalg.svd(G, full_matrices=False)
            keep = sv > 1e-9 * max(float(sv.max(initial=0.0)), 1e-300)
            self._q, self._f = q[:, keep], 1.0 / np.sqrt(1.0 + sv[keep] ** 2) - 1.0
        Xw = np.asarray(self.pb.X0) * self.pb.w[:, None]
        self.U0 = stats.orthonormal_basis(self._t(Xw))

    def _t(self, A: np.ndarray) -> np.ndarray:
        if self._q is None:
            return A
        return A + self._q @ (self._f[:, None] * (self._q.T @ A))

    def w(self, X: np.ndarray) -> np.ndarray:
        return self._t(super().w(X))


def regenerate(r: dict[str, Any]) -> tuple[list[dict[str, Any]], Any, dict[str, Any]]:
    """The case's rows with its effect, the drawn effect and its summary, from the run's
    line (the same draws as ``run.run_case``)."""
    eff = r["effect"]
    case = variant_case(draw_case(int(r["case_seed"])), r.get("variant", "none"))
    drawn, info = draw_effect(eff["effect"], case, float(eff["size"]))
    return simulate(drawn.case, drawn), drawn, info


def signature_g(rows: list[dict[str, Any]], drawn: Any) -> np.ndarray:
    """(N, 3) g: the effect in the recording, noise-free (module docstring)."""
    if drawn.name != "temperature_sensor":
        return np.array([r["extra_g"] for r in rows])
    s = drawn.case.sensor
    out = []
    for i, r in enumerate(rows):
        ref = np.array([r["ref_x"], r["ref_y"], r["ref_z"]])
        out.append(s.output_g(ref, r["die_c"]) - s.output_g(ref, r["die_c"] + drawn.channel_c(i)))
    return np.array(out)


def noise_check(o: Oracle, rows: list[dict[str, Any]]) -> float:
    """RMS of the recording less its noise-free output (the rows' drawn error ``err_g``:
    the recorded mean − the effect − the sensor at its reference and die temperature),
    whitened as the diagnosis does and off its base: ≈ 1 when the oracle's units hold."""
    raw = np.column_stack([o.rec.columns[x] for x in ("ax", "ay", "az")])
    out_e = np.array([[r["ax"], r["ay"], r["az"]] for r in rows]) - np.array(
        [r["err_g"] for r in rows])
    chk = o.off(o.U0, o.w((raw - out_e)[:, :, None]))[:, 0]
    return float(np.sqrt(np.mean(chk**2)))


def null_check(o: Oracle, sig_g: np.ndarray) -> float:
    """RMS of the recording less the signature, whitened and off the base: what the base
    leaves of the effect-free recording, the temperature channel's own error (its noise
    and a quantiser's per-plateau rounding, which the oracle's noise leaves out) included;
    near ``noise_check`` when that error is small."""
    raw = np.column_stack([o.rec.columns[x] for x in ("ax", "ay", "az")])
    e = o.off(o.U0, o.w((raw - sig_g)[:, :, None]))[:, 0]
    return float(np.sqrt(np.mean(e**2)))


def hardest_single(sep: dict[str, Any], rivals: list[str]) -> float | None:
    """The smallest power in the effect's columns against one rival at a time (the rival
    most like it); the classification takes all rivals at once, as gen2's does."""
    one = [sep[x]["power_cols"] for x in rivals if x in sep and sep[x]["rivals_modelled"]]
    return min(one) if one else None


def _alternatives(entry: dict[str, Any], kid: str) -> list[str]:
    """``Confusion.alternatives`` on the report's JSON of one entry."""
    return Confusion(tuple(entry.get("effects") or ()), entry.get("why", ""),
                     versus=tuple(entry.get("versus") or ())).alternatives(kid)


def best_jump(o: Oracle, kid: str, sig: np.ndarray) -> str | None:
    """The jump at the T* (between two plateau temperatures) that fits ``sig`` best, as a
    rival name ``rival_columns`` reads."""
    best, name = np.inf, None
    for th in thresholds_c(o.ctx.step_temp_c):
        cand = f"{JUMP} ≈ {th:.6f}"
        for X in rival_columns(o, cand, kid, sig):
            left = float(np.sum(o.off(o.basis([X]), sig) ** 2))
            if left < best:
                best, name = left, cand
    return name


def named_rivals(doc: dict[str, Any], kid: str, o: Oracle, sig: np.ndarray) -> list[str]:
    """The rivals the diagnosis named beside ``kid`` (module docstring), as names
    ``rival_columns`` reads (a catalogue id, a phrase of the candidates, ``SLOT``,
    ``LEVELS`` + axes)."""
    out: list[str] = []
    for f in doc.get("findings") or []:
        where = f.get("where") or {}
        cands = [str(c) for c in where.get("candidates") or []]
        if f.get("effect") == "not_identifiable":
            # beside the effect, or (the effect not among them) what the diagnosis put
            # forward for the structure instead: the oracle asks whether the truth could
            # have been told from that answer (``kid_named`` says which)
            out += [c for c in cands if c != kid]
        for p in where.get("places") or []:
            if isinstance(p, dict) and p.get("not_named") == kid:
                m = re.search(r"too few input levels on the term's axes \(([^;]*);",
                              p.get("why", ""))
                if m:
                    axes = sorted({a.split(":")[0].strip() for a in m.group(1).split(",")})
                    out.append(LEVELS + ",".join(axes))
    why = {n.get("effect"): n.get("why", "") for n in doc.get("not_identifiable") or []}
    m = re.match(r"not separable from (.*?)(?: here)?:", why.get(kid, ""))
    if m:
        out += [x.strip() for x in m.group(1).split(",") if x.strip() in BY_ID]
    for entry in (doc.get("protocol") or {}).get("not_separable") or []:
        if kid not in (entry.get("effects") or []):
            continue
        out += _alternatives(entry, kid)
        if any(x.startswith(JUMP) for x in entry.get("outside_catalogue") or []):
            jump = best_jump(o, kid, sig)
            out += [jump] if jump else []
        if SAME_ORDER in entry.get("why", ""):
            out.append(SLOT)
    if BY_ID[kid].input_only and time_and_position_confounded(
            o.ctx.steps, o.ctx.positions, o.ctx.t_s):
        out.append(SLOT)  # as gen2's outcome: the slots span every function of position
    return list(dict.fromkeys(SLOT if x == SLOT_SETTLING else x for x in out))


def kid_named(doc: dict[str, Any], kid: str) -> bool:
    """The diagnosis names the effect as a candidate: among a ``not_identifiable``
    finding's candidates, withheld at a place of an ``unexplained`` one, or "not separable
    from" something in its ``not_identifiable`` entry."""
    for f in doc.get("findings") or []:
        where = f.get("where") or {}
        if kid in (where.get("candidates") or []) or any(
                isinstance(p, dict) and p.get("not_named") == kid
                for p in where.get("places") or []):
            return True
    why = {n.get("effect"): n.get("why", "") for n in doc.get("not_identifiable") or []}
    return why.get(kid, "").startswith("not separable from")


def _worst(sep: dict[str, Any], rivals: list[str]) -> dict[str, Any]:
    return sep["all rivals" if len(rivals) > 1 else (rivals[0] if rivals else "base")]


def oracle_case(out: Path, r: dict[str, Any], alpha: float = ALPHA) -> dict[str, Any] | None:
    """One case's oracle row (None where the case was absorbed or the gate refused)."""
    kid = r["effect"]["effect"]
    status = score_class(kid, r)
    if status in ("absorbed", "cannot judge"):
        return None
    rows, drawn, info = regenerate(r)
    tmp = Path(tempfile.mkdtemp(prefix="gen3sep-"))
    try:
        name = f"gen3-{r['index']:04d}.csv"
        csv = tmp / name
        lsb = drawn.case.thermal.channel_lsb_c if "t-lsb-column" in r.get(
            "variant", "none").split("+") else None
        write_csv(rows, csv, sensor_lsb_c=lsb)
        kept = sorted((out / "alarms").glob(f"gen3-*-{r['index']:04d}.csv"))
        same = None if not kept else kept[0].read_bytes() == csv.read_bytes()
        o = Oracle(csv)
        chan = channel_noise(drawn.case, rows)
        oc = ChannelOracle(csv, chan.slope, chan.steps, chan.plateau_var)
        sig_g = signature_g(rows, drawn)
        sig = oc.w(sig_g[:, :, None])
        rivals: list[str] = []
        named = None
        if status == "not established":
            cache = out / "diagnoses" / f"{r['index']:04d}.json"
            if cache.exists():
                doc = json.loads(cache.read_text(encoding="utf-8"))
            else:
                doc = diagnose_json(csv)
                cache.parent.mkdir(exist_ok=True)
                cache.write_text(json.dumps(doc, default=str), encoding="utf-8")
            rivals = named_rivals(doc, kid, oc, sig)
            named = kid_named(doc, kid)
        key = {"catalogue_id": kid, "pattern": {"rows": list(drawn.outlier_rows)}}
        sep = separability(oc, key, sig_g, rivals, alpha / 2)
        plain = separability(o, key, sig_g, rivals, alpha / 2)
        nu = r["features"].get("heavy_nu")
        if BY_ID[kid].per_reading and nu:  # the outlier test against the drawn tail
            for sp in (sep, plain):
                for v in sp.values():
                    v["power_cols_gaussian"] = v["power_cols"]
                    v["power_cols"] = tail_power(v["lam_cols"], v["dof"], alpha / 2,
                                                 o.ctx.n, float(nu))
        k_fam, g_own = family_multiplicity(o.ctx, kid)
        b = sep["base"]
        if BY_ID[kid].per_reading:  # tail_power spreads the level over the readings itself
            power_family = tail_power(b["lam_cols"], b["dof"], alpha / 2 / k_fam, o.ctx.n,
                                      float(nu) if nu else np.inf)
        else:
            power_family = chi2_power(b["lam_cols"], b["dof"], alpha / 2 / (k_fam * g_own))
        check, null = noise_check(o, rows), null_check(o, sig_g)
        null_c = null_check(oc, sig_g)
    finally:
        shutil.rmtree(tmp)
    def _class(sp: dict[str, Any]) -> str:
        if status == "missed":
            return ("missed detectable" if sp["base"]["power_cols"] >= POWER_SEPARABLE
                    else "missed undetectable")
        return oracle_class("not_established" if status == "not established" else status,
                            sp, rivals)

    cls = _class(sep)
    f = r["features"]
    return {"effect": kid, "index": r["index"], "case_seed": r["case_seed"],
            "protocol": f"{f['plateaus']} pl {f['order']}", "status": status,
            "class": cls, "rivals": rivals, "csv_same_as_kept": same,
            "signal_rms_ug": float(np.sqrt(np.mean(sig_g**2)) * 1e6), "noise_s": o.s,
            "class_without_channel": _class(plain), "sep_without_channel": plain,
            "plateau_var_c2": chan.plateau_var, "null_rms_with_channel": null_c,
            "hand": f["fixture"] == "hand", "t_lsb_c": f["t_lsb_c"],
            "kid_named": named, "share_left": info.get("share_left"),
            "base_absorbs": info.get("share_left") is not None
            and info["share_left"] < 1.0 - BY_ID[kid].absorbed_max,
            "check_noise_rms": check, "null_rms": null,
            "power_hardest_single": hardest_single(sep, rivals),
            "unmodelled_rivals": [x for x in rivals if not sep.get(x, {}).get(
                "rivals_modelled")],
            "readings": int(o.ctx.n), "sep": sep,
            "families": k_fam, "own_multiplicity": g_own, "power_family": power_family,
            "size": float(info.get("size", r["effect"]["size"]))}


CLASSES = ("right", "honest", "deficit", "wrong", "missed detectable", "missed undetectable")


def _ci(k: int, n: int) -> str:
    if not n:
        return "–"
    lo, hi = clopper_pearson(k, n)
    return f"{k}/{n} [{100 * lo:.0f}, {100 * hi:.0f}] %"


def summary(rows: list[dict[str, Any]], key: str = "class") -> list[str]:
    """The per-effect table of the classes under ``key`` (``class``: with the channel's
    rounding; ``class_without_channel``: the diagnosis' whitening alone)."""
    by: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for r in rows:
        c = r[key]
        by[r["effect"]][c] += 1
        if c in ("honest", "deficit") and not r["kid_named"]:
            by[r["effect"]][c + " unnamed"] += 1
        by[r["effect"]]["missed detectable absorbed"] += (c == "missed detectable"
                                                          and r["base_absorbs"])
    head = ["| effect | n | right | not established: honest (effect not among the "
            "candidates) | not established: power deficit (effect not among the candidates) "
            "| wrong | missed: detectable by the oracle (the base absorbs > 99 % of the "
            "pattern: withheld by the diagnosis' absorbed-share rule) | missed: not detectable | "
            "right among oracle-separable (95 %) |", "|---|---|---|---|---|---|---|---|---|"]
    tot: dict[str, int] = defaultdict(int)

    def line(name: str, c: dict[str, int]) -> str:
        n = sum(c[k] for k in CLASSES)
        sep_n = c["right"] + c["deficit"] + c["wrong"] + c["missed detectable"]
        cells = [str(c[k]) + (f" ({c[k + ' unnamed']})" if k in ("honest", "deficit") else
                              f" ({c[k + ' absorbed']})" if k == "missed detectable" else "")
                 for k in CLASSES]
        return (f"| {name} | {n} | " + " | ".join(cells)
                + f" | {_ci(c['right'], sep_n)} |")

    for e in sorted(by):
        head.append(line(f"`{e}`", by[e]))
        for k in (*CLASSES, "honest unnamed", "deficit unnamed", "missed detectable absorbed"):
            tot[k] += by[e][k]
    head.append(line("all", tot))
    return head


def multiplicity_split(rows: list[dict[str, Any]]) -> list[str]:
    """The detectable misses split by the family test's multiplicity (``power_family``):
    detectable even at α/2 / (K·G), or only at one test's α/2."""
    by: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    for r in rows:
        if r["class"] == "missed detectable" and not r["base_absorbs"]:
            by[r["effect"]][0 if r["power_family"] >= POWER_SEPARABLE else 1] += 1
    out = ["| effect | missed, tested (not absorbed): detectable at the family's level "
           "α/2 / (K·G) | only at one test's α/2 |", "|---|---|---|"]
    tot = [0, 0]
    for e in sorted(by):
        out.append(f"| `{e}` | {by[e][0]} | {by[e][1]} |")
        tot = [tot[0] + by[e][0], tot[1] + by[e][1]]
    out.append(f"| all | {tot[0]} | {tot[1]} |")
    return out


def markdown(rows: list[dict[str, Any]]) -> str:
    head = summary(rows)
    head += ["", "The tested misses by the family test's multiplicity (K families testable "
             "here, G the effect's grid values or readings):", ""] + multiplicity_split(rows)
    head += ["", "Without the temperature channel's rounding (the diagnosis' whitening "
             "alone):", ""] + summary(rows, "class_without_channel")
    head += ["", "Table fixture only (a hand fixture's re-seating turns are noise the "
             "diagnosis' whitening spreads over every row):", ""] + summary(
                 [r for r in rows if not r["hand"]])
    head += ["", "| effect | case | protocol | class | rivals named | λ base (dof) | power base "
             "| λ after rivals (dof) | power after rivals | λ known-shape after rivals "
             "| hardest single rival's power | class without the channel | check rms (null rms) "
             "|", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["status"] not in ("not established", "missed"):
            continue
        b, w = r["sep"]["base"], _worst(r["sep"], r["rivals"])
        riv = "; ".join(x[:48] for x in r["rivals"]) or "–"
        cls = r["class"] + (" (not among the candidates)" if r["kid_named"] is False else "")
        head.append(f"| `{r['effect']}` | {r['index']} | {r['protocol']} | {cls} | "
                    f"{riv} | {b['lam_cols']:.1f} ({b['dof']}) | {b['power_cols']:.2f} | "
                    f"{w['lam_cols']:.1f} ({w['dof']}) | {w['power_cols']:.2f} | "
                    f"{w['lam_known']:.1f} | {_p(r['power_hardest_single'])} | "
                    f"{r['class_without_channel']} | "
                    f"{r['check_noise_rms']:.2f} ({r['null_rms']:.2f}) |")
    return "\n".join(head) + "\n"


def _p(x: float | None) -> str:
    return "–" if x is None else f"{x:.2f}"


def _line(r: dict[str, Any]) -> str:
    b, w = r["sep"]["base"], _worst(r["sep"], r["rivals"])
    return (f"{r['effect'][:18]:18s} {r['index']:3d} {r['protocol']:14s} {r['class']:20s} "
            f"base λ={b['lam_cols']:.1f}/{b['dof']} p={b['power_cols']:.2f} known "
            f"λ={b['lam_known']:.1f} | vs {'; '.join(x[:30] for x in r['rivals']) or '-'}: "
            f"λ={w['lam_cols']:.1f}/{w['dof']} p={w['power_cols']:.2f} "
            f"single {_p(r['power_hardest_single'])} unmodelled {r['unmodelled_rivals']} "
            f"check {r['check_noise_rms']:.2f} null {r['null_rms']:.2f} "
            f"kept {r['csv_same_as_kept']}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--alpha", type=float, default=ALPHA)
    ap.add_argument("--cases", default=None, help="comma list of case indices (default all)")
    ap.add_argument("--results", type=Path, default=None, help="write STEM.md and STEM.json")
    a = ap.parse_args(argv)
    pick = {int(x) for x in a.cases.split(",")} if a.cases else None
    rows = []
    for out in a.runs:
        for line in (out / "cases.jsonl").read_text(encoding="utf-8").splitlines():
            if not line.strip():
                continue
            r = json.loads(line)
            if "effect" not in r or (pick is not None and r["index"] not in pick):
                continue
            row = oracle_case(out, r, a.alpha)
            if row is not None:
                rows.append(row)
                print(_line(row), file=sys.stderr, flush=True)
    md = markdown(rows)
    print(md)
    if a.results:
        a.results.with_suffix(".md").write_text(md, encoding="utf-8")
        a.results.with_suffix(".json").write_text(json.dumps(rows, indent=1, default=str),
                                                  encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
