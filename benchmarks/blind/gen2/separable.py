"""Oracle separability of the second generator's catalogue cases (issue 22).

    python -m benchmarks.blind.gen2.separable --realdata DIR --out OUT [--multiple 2]
                                              [--results STEM]

For each catalogue case of an earlier ``gen2.run`` (``OUT/cases``, ``OUT/keys``,
``OUT/diagnoses.json``) asks: could the data have told the true effect from the rival(s)
the diagnosis withheld it beside, at this size? The generator knows the effect's own
signature in the recording: its noise-free output with the effect minus without it, the
same seed, sensor, placement and protocol (``true_signal_g``; a channel step is the
output at the die temperature minus the base's prediction at the stepped channel). That
signature, in the diagnosis' own residual space (``build_problem``: the base model, its
whitening, the recording's own noise scale as ``diagnose`` estimates it), is projected
off the base model and the rival's columns (the catalogue's regressors of the rival at
its best θ for the signature; a plateau's local block for "a change confined to step k";
the jump column for "a jump of the output where the temperature crosses"; the turn of
each reference direction for ``turntable_geometry`` beside an input-only term). Two
noncentralities are reported:

* ``lam_cols``: the part of the signature the *true effect's own catalogue columns* (its
  regressors at the θ that fits the signature best) still carry after base and rival — a
  test in the diagnosis' parametrisation with ``dof`` = their rank after the projection;
* ``lam_known``: all of the signature off base and rival — the most powerful test of a
  signal of known shape (one dof), an upper bound no parametrisation can beat.

Power = P(χ²_dof(λ) > χ²_dof,1−α/2), α/2 the level of the diagnosis' family test. A
"not established" answer is *honest* when the oracle's power in the columns is below
one half against the rival it was withheld beside, a *power deficit* otherwise.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections import defaultdict
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats as sps

from benchmarks.blind.gen2 import protocol as pr
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir
from benchmarks.blind.gen2.score import _not_confirmed, _not_separable
from benchmarks.blind.gen2.sensor import draw_sensor
from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.base import per_axis
from calibration.discrepancy.effects.scale_nonlinearity import LEVEL_G
from calibration.discrepancy.effects.thermal_lag import WARMUP_TAU_GRID_S
from calibration.discrepancy.effects.thermal_lag import _age_s as lag_age_s
from calibration.discrepancy.effects.turntable_geometry import turn_columns
from calibration.discrepancy.level import ALPHA
from calibration.discrepancy.plateau_settling import since_plateau_start_s
from calibration.discrepancy.problem import build_problem
from calibration.discrepancy.protocol_order import (
    slot_offset_columns,
    time_and_position_confounded,
)
from calibration.discrepancy.slot_settling import SLOT_SETTLING
from calibration.discrepancy.temperature_jump import jump_column, thresholds_c
from calibration.recording import read_recording

SLOT = "a settling after each move, the same on every plateau"
LEVELS = "any function of each axis's input levels on "  # + the axes, e.g. "x,z"
POWER_SEPARABLE = 0.5  # oracle power above which "not established" is a power deficit


def _protocol(detail: dict) -> pr.Protocol2:
    return pr.Protocol2(**{k: tuple(v) if isinstance(v, list) else v
                           for k, v in detail.items()})


def true_signal_g(key: dict, pools) -> tuple[np.ndarray, np.ndarray]:
    """(N,3) g: the case's effect in its recording, noise-free (the generator's own draws),
    and the noise-free output with it (the recording less its noise: a check).

    ``simulate.record`` seats each visit with rng(seed + 1)'s first draw and builds the
    scene from rng(seed): both are repeated here with and without the effect. A channel
    step changes no output; its signature is what the base model, fitted on the stepped
    channel, cannot follow: output at the die temperature minus output at the channel's.
    """
    proto, pat, seed = _protocol(key["protocol_detail"]), key["pattern"], key["seed"]
    sensor = draw_sensor(np.random.default_rng(seed))
    eid, m = key["effect"], float(key["magnitude"])

    def seated(sc: sim.Scene) -> sim.Scene:
        ang = (np.random.default_rng(seed + 1).choice(pools.placement, (len(sc.t_s), 3))
               * proto.placement_rad)
        return replace(sc, force_g=sc.force_g + np.cross(ang, sc.force_g))

    sc_e = seated(sim.scene(proto, eid, m, pat, seed))
    out_e = sim.noise_free_output(sensor, sc_e, eid, m, pat)
    if eid == "temperature_sensor":
        ch_e = sim.recorded_temperature_c(sc_e, proto, eid, m, pat)["sensor_c"]
        ch_0 = sim.recorded_temperature_c(sc_e, proto, None, 0.0, pat)["sensor_c"]
        return out_e - sensor.output_g(sc_e.force_g, sc_e.die_c + (ch_e - ch_0)), out_e
    sc_0 = seated(sim.scene(proto, None, 0.0, pat, seed))
    return out_e - sim.noise_free_output(sensor, sc_0, None, 0.0, pat), out_e


class Oracle:
    """The diagnosis' base problem of one recording, and projections in its noise units."""

    def __init__(self, csv: Path) -> None:
        self.rec = read_recording(csv)
        self.pb = build_problem(self.rec)
        self.ctx = self.pb.ctx
        Xw = np.asarray(self.pb.X0) * self.pb.w[:, None]
        self.U0 = stats.orthonormal_basis(Xw)
        yw = self.pb.y * self.pb.w
        e = yw - self.U0 @ (self.U0.T @ yw)
        dof = np.sqrt(self.pb.m / max(self.pb.m - self.U0.shape[1], 1))
        self.s = float(stats.robust_scale(e[:, None], dof)[0])  # diagnose's noise scale

    def w(self, X: np.ndarray) -> np.ndarray:
        """(N,3,k) raw-space columns → whitened residual space (m,k), in noise units."""
        return self.pb.whiten(self.pb.lift(X)) / self.s

    def basis(self, extra: list[np.ndarray]) -> np.ndarray:
        return stats.orthonormal_basis(np.hstack([self.U0] + extra)) if extra else self.U0

    def off(self, U: np.ndarray, A: np.ndarray) -> np.ndarray:
        return A - U @ (U.T @ A)


def rival_columns(o: Oracle, rival: str, key_id: str, sig: np.ndarray) -> list[np.ndarray]:
    """Whitened column sets a rival may take (the oracle keeps the one closest to ``sig``)."""
    ctx = o.ctx
    m = re.match(r"a change confined to step (\d+)", rival)
    if m:
        step = int(m.group(1))
        u = np.column_stack([np.ones(ctx.n), ctx.input_g]) * (ctx.steps == step)[:, None]
        block = np.zeros((ctx.n, 3, 12))
        for a in range(3):
            block[:, a, 4 * a:4 * a + 4] = u
        return [o.w(block)]
    if rival.startswith(LEVELS):
        # a free per-axis output at each input level of those axes (LEVEL_G apart)
        cols = []
        for name in rival[len(LEVELS):].split(","):
            a = "xyz".index(name)
            v = ctx.input_g[:, a]
            lv = np.concatenate([[0], np.cumsum(np.diff(np.sort(v)) > LEVEL_G)])
            ids = np.empty(ctx.n, int)
            ids[np.argsort(v)] = lv
            for j in range(int(ids.max()) + 1):
                x = np.zeros((ctx.n, 3, 1))
                x[ids == j, a, 0] = 1.0
                cols.append(x)
        return [o.w(np.concatenate(cols, axis=2))] if cols else []
    if rival == SLOT:
        # a free per-axis offset at each slot of the (repeated) visiting order: a settling
        # after each move that repeats on every plateau, whatever its shape (the columns
        # the diagnosis' slot_settling check uses)
        return [o.w(slot_offset_columns(ctx.steps, ctx.positions, ctx.t_s))]
    m = re.match(r"a settling after each plateau's start.*?τ ≈ ([\d.]+) s", rival)
    if m:  # plateau_settling.py's rival: one per-axis decay after each plateau's start
        t = since_plateau_start_s(ctx)
        return [o.w(per_axis(ctx, np.exp(-t / float(m.group(1)))))]
    m = re.match(r"a jump of the output where the temperature crosses ≈ (-?[\d.]+)", rival)
    if m:
        th = min(thresholds_c(ctx.step_temp_c), key=lambda t: abs(t - float(m.group(1))))
        return [o.w(per_axis(ctx, jump_column(ctx, th)))]
    if rival == "self_heating" and key_id == "thermal_lag":
        # what ThermalLag.not_told_from puts beside the lag's amplitude: a warm-up after
        # power-on, the model's own ∂raw/∂T times exp(−age/τw), and the lag's own nuisance
        # (its second column: the first plateau's unknown start); one option per τw of its
        # grid and τ of the lag's. The check tests the amplitude alone after both.
        age = lag_age_s(ctx)
        lag = BY_ID["thermal_lag"]
        return [np.hstack([o.w(-ctx.draw_dtemp_g_per_c[:, :, None]
                               * np.exp(-age / t)[:, None, None]),
                           o.w(lag.regressors(ctx, th)[:, :, 1:])])
                for t in WARMUP_TAU_GRID_S for th in lag.grid(ctx)]
    if rival not in BY_ID:
        return []
    eff = BY_ID[rival]
    out = []
    if eff.identifiable(ctx)[0] and not eff.per_reading:
        out += [o.w(eff.regressors(ctx, th)) for th in eff.grid(ctx)]
    if rival == "turntable_geometry" and BY_ID[key_id].input_only:
        u = ctx.input_g / np.linalg.norm(ctx.input_g, axis=1, keepdims=True)
        out.append(o.w(turn_columns(u)))  # what diagnose._turned_or_bent puts beside
    return out


def chi2_power(lam: float, dof: int, level: float) -> float:
    """P(χ²_dof(λ) > χ²_dof quantile at 1 − ``level``): a test of ``dof`` columns' power."""
    if dof <= 0:
        return 0.0
    return float(sps.ncx2.sf(sps.chi2.isf(level, dof), dof, max(lam, 1e-12)))


def separability(o: Oracle, key: dict, s_g: np.ndarray, rivals: list[str],
                 level: float) -> dict[str, Any]:
    """λ and power of the true effect against base + each rival (and all rivals at once)."""
    eff = BY_ID[key["catalogue_id"]]
    sig = o.w(s_g[:, :, None])
    own: list[np.ndarray] = []
    if eff.per_reading:
        rows = key["pattern"]["rows"]
        own = [o.w(eff.regressors(o.ctx, float(r))) for r in rows]
    else:  # also where the protocol-level check withholds it: the oracle asks the data
        own = [o.w(eff.regressors(o.ctx, th)) for th in eff.grid(o.ctx)]
    out: dict[str, Any] = {}
    sets = [("base", [])] + [(r, [r]) for r in rivals] + (
        [("all rivals", rivals)] if len(rivals) > 1 else [])
    for name, rs in sets:
        # each rival at its best fit to the signature (the smallest λ it leaves)
        chosen: list[np.ndarray] = []
        for r in rs:
            opts = rival_columns(o, r, key["catalogue_id"], sig)
            if not opts:
                continue
            chosen.append(min(opts, key=lambda X: float(np.sum(
                o.off(o.basis([X]), sig) ** 2))))
        U = o.basis(chosen)
        r_sig = o.off(U, sig)[:, 0]
        lam_known = float(r_sig @ r_sig)
        best = {"lam_cols": 0.0, "dof": 0, "power_cols": 0.0}
        for X in own:
            Xo = o.off(U, X)
            Q = stats.orthonormal_basis(Xo) if np.linalg.norm(Xo) > 1e-9 else Xo[:, :0]
            lam = float(np.sum((Q.T @ r_sig) ** 2))
            pw = chi2_power(lam, Q.shape[1], level)
            if pw > best["power_cols"]:
                best = {"lam_cols": lam, "dof": int(Q.shape[1]), "power_cols": pw}
        if eff.per_reading:  # a max over readings: the level per reading (Bonferroni)
            best["power_cols"] = chi2_power(best["lam_cols"], best["dof"], level / o.ctx.n)
        out[name] = {"lam_known": lam_known, "power_known": chi2_power(lam_known, 1, level),
                     "rivals_modelled": len(chosen), **best}
    return out


def outcome(d: dict, key: dict) -> tuple[str, list[str]]:
    """right / not_established / wrong / missed, and the rivals the diagnosis named."""
    kid = key["catalogue_id"]
    findings = d.get("findings") or []
    top = findings[0].get("effect") if findings else None
    if top == kid:
        return "right", list(BY_ID[kid].confusers)
    where = (findings[0].get("where") or {}) if findings else {}
    listed = {n.get("effect"): n.get("why", "") for n in d.get("not_identifiable") or []}
    if _not_confirmed(d, kid):
        # structure found and withheld by a held-out or physics check (not_confirmed.py,
        # diagnose._physics_checks): no rival; the oracle asks whether it is beyond noise.
        # Except where the check is the protocol's: too few input levels on the term's axes
        # (scale_nonlinearity.bends_otherwise), where bias, scale, a² and a³ fit any function
        # of those levels, a converter error in a band of codes included (outside the
        # catalogue; the outside sets draw it): that function is the rival.
        levels = [re.search(r"too few input levels on the term's axes \(([^;]*);", p.get("why", ""))
                  for p in where.get("places") or [] if p.get("not_named") == kid]
        axes = sorted({a.split(":")[0].strip() for m in levels if m
                       for a in m.group(1).split(",")})
        return "not_established", ([LEVELS + ",".join(axes)] if axes else [])
    if _not_separable(d, kid) or (top in (None, "unexplained") and kid in listed):
        rivals = [c for c in where.get("candidates") or [] if c != kid] if (
            top == "not_identifiable") else []
        why = listed.get(kid, "")
        m = re.match(r"not separable from (.*?)(?: here)?:", why)
        if m:
            rivals += [x.strip() for x in m.group(1).split(",") if x.strip() in BY_ID]
        if "same order on every plateau" in why or SLOT_SETTLING in why or (
                (kid == "turntable_geometry" or BY_ID[kid].input_only)
                and time_and_position_confounded(
                    *(np.asarray(d["_order"][k]) for k in ("steps", "positions", "t_s")))):
            # the protocol-level reason turntable_geometry is withheld (its identifiable()),
            # even where another check's reason was recorded over it; an input-only term
            # (cross_coupling, scale_nonlinearity) is withheld by slot_settling_alike on
            # such a protocol whatever an earlier check (a turn of the reference) said: the
            # slots span every function of the position
            rivals.append(SLOT)
        # slot_settling's candidate is this oracle's SLOT (the same columns)
        return "not_established", list(dict.fromkeys(SLOT if r == SLOT_SETTLING else r
                                                     for r in rivals))
    if top is None or top == "unexplained":
        return "missed", []
    return "wrong", []


def classify(status: str, sep: dict, rivals: list[str]) -> str:
    if status != "not_established":
        return status
    worst = sep["all rivals" if len(rivals) > 1 else (rivals[0] if rivals else "base")]
    return ("deficit" if worst["power_cols"] >= POWER_SEPARABLE else "honest")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--multiple", type=float, default=2.0)
    ap.add_argument("--alpha", type=float, default=ALPHA)
    ap.add_argument("--cases", default=None, help="comma list of cases (default: all)")
    ap.add_argument("--results", type=Path, default=None)
    a = ap.parse_args(argv)
    pools = load_pools(realdata_dir(a.realdata))
    diags = json.loads((a.out / "diagnoses.json").read_text())
    keys = {p.stem: json.loads(p.read_text()) for p in sorted((a.out / "keys").glob("*.json"))}
    pick = set(a.cases.split(",")) if a.cases else None
    rows = []
    for c, k in keys.items():
        if k["kind"] != "catalogue" or k["multiple"] != a.multiple or (pick and c not in pick):
            continue
        o = Oracle(a.out / "cases" / f"{c}.csv")
        order = {"steps": o.ctx.steps, "positions": o.ctx.positions, "t_s": o.ctx.t_s}
        status, rivals = outcome({**diags[c], "_order": order}, k)
        s_g, out_e = true_signal_g(k, pools)
        raw = np.column_stack([o.rec.columns[x] for x in ("ax", "ay", "az")])
        # the recording less its noise-free output, whitened as the diagnosis does and off
        # the base: its noise alone, rms ≈ 1 when the signature is this recording's
        chk = o.off(o.U0, o.w((raw - out_e)[:, :, None]))[:, 0]
        sep = separability(o, k, s_g, rivals, a.alpha / 2)
        by_check = status == "not_established" and _not_confirmed(diags[c], k["catalogue_id"])
        rows.append({"case": c, "effect": k["effect"], "protocol": k["protocol"],
                     "status": status, "rivals": rivals, "by_check": by_check,
                     "class": classify(status, sep, rivals),
                     "signal_rms_ug": float(np.sqrt(np.mean(s_g ** 2)) * 1e6),
                     "noise_s": o.s, "readings": int(o.ctx.n), "sep": sep,
                     "check_noise_rms": float(np.sqrt(np.mean(chk ** 2)))})
        print(_line(rows[-1]), file=sys.stderr)
    return emit(markdown(rows), rows, a.results)


def emit(md: str, rows: list[dict], results: Path | None) -> int:
    """Print the table; with ``results``, write it as STEM.md and the rows as STEM.json."""
    print(md)
    if results:
        results.with_suffix(".md").write_text(md)
        results.with_suffix(".json").write_text(json.dumps(rows, indent=1))
    return 0


def _line(r: dict) -> str:
    s = r["sep"]
    worst = s["all rivals" if len(r["rivals"]) > 1 else (r["rivals"][0] if r["rivals"]
                                                          else "base")]
    return (f"{r['case']} {r['effect'][:18]:18s} {r['protocol'][:38]:38s} {r['status']:15s} "
            f"{r['class']:8s} base λ={s['base']['lam_cols']:.1f}/{s['base']['dof']} "
            f"p={s['base']['power_cols']:.2f} | vs {','.join(r['rivals']) or '-'}: "
            f"λ={worst['lam_cols']:.1f}/{worst['dof']} p={worst['power_cols']:.2f} "
            f"known λ={worst['lam_known']:.1f} sig {r['signal_rms_ug']:.1f} µg "
            f"check {r['check_noise_rms']:.2f}")


def markdown(rows: list[dict]) -> str:
    by = defaultdict(lambda: defaultdict(int))
    exp = defaultdict(float)
    for r in rows:
        by[r["effect"]][r["class"]] += 1
        by[r["effect"]]["by_check"] += r["class"] == "deficit" and r["by_check"]
        if r["status"] == "not_established":
            s = r["sep"]
            exp[r["effect"]] += s["all rivals" if len(r["rivals"]) > 1 else (
                r["rivals"][0] if r["rivals"] else "base")]["power_cols"]
    cols = ("right", "honest", "deficit", "wrong", "missed")
    out = ["| effect | n | right | not established, oracle inseparable (honest) | "
           "not established, oracle separable (power deficit; of which withheld by a held-out "
           "or physics check) | wrong | missed | "
           "oracle's expected separations among the not established | right among "
           "separable |", "|---|---|---|---|---|---|---|---|---|"]
    tot = defaultdict(int)
    for e in sorted(by):
        n = sum(by[e][c] for c in cols)
        sep_n = by[e]["right"] + by[e]["deficit"] + by[e]["wrong"] + by[e]["missed"]
        cells = [str(by[e][c]) + (f" ({by[e]['by_check']})" if c == "deficit" else "")
                 for c in cols]
        out.append(f"| {e} | {n} | " + " | ".join(cells)
                   + f" | {exp[e]:.1f} | {by[e]['right']}/{sep_n} |")
        for c in (*cols, "by_check"):
            tot[c] += by[e][c]
        tot["n"] += n
    sep_n = tot["right"] + tot["deficit"] + tot["wrong"] + tot["missed"]
    lo, hi = clopper_pearson(tot["right"], sep_n) if sep_n else (0.0, 0.0)
    out.append(f"| all | {tot['n']} | " + " | ".join(
        str(tot[c]) + (f" ({tot['by_check']})" if c == "deficit" else "") for c in cols)
               + f" | {sum(exp.values()):.1f} | {tot['right']}/{sep_n} "
               f"({100 * lo:.1f}–{100 * hi:.1f} %) |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
