"""Per case of a temperature-channel step on the second generator: found, shaped, separable?

    python -m benchmarks.blind.channel_step_cases --realdata DIR --out OUT [--multiple 2]

``OUT`` is a ``benchmarks.blind.gen2.run`` output directory (``cases/``, ``keys/``,
``diagnoses.json``). For every ``temperature_sensor`` case it prints, next to what the
diagnosis reported: the generator's exact-shape λ at the case's size (``detect.py``, true σ);
the catalogue term's z and fitted step δ̂ ± sd at the true plateau after the base model; and
how much of the term's remnant survives a free change of the worst single plateau (the
alternative ``diagnose``'s one-plateau check frees: per axis 1, a_x, a_y, a_z on that
plateau) — the term's share there (``keep``) and its z after it. ``keep`` ≈ 0 means the
protocol cannot tell the step from "that plateau differs" at any size (issue 22).
"""

from __future__ import annotations

import argparse
import importlib
import json
from pathlib import Path

import numpy as np

from benchmarks.blind.gen2 import detect
from benchmarks.blind.gen2 import protocol as gp
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.problem import LinearProblem, build_problem
from calibration.recording import read_recording

_diag = importlib.import_module("calibration.discrepancy.diagnose")
STEP = BY_ID["temperature_sensor"]


def plateau_block(pb: LinearProblem, step: int) -> np.ndarray:
    """Whitened (m, 12) free change of one plateau: per axis 1, a_x, a_y, a_z there."""
    ctx = pb.ctx
    u = np.column_stack([np.ones(ctx.n), ctx.input_g]) * (ctx.steps == step)[:, None]
    block = np.zeros((ctx.n, 3, 12))
    for a in range(3):
        block[:, a, 4 * a:4 * a + 4] = u
    return pb.whiten(pb.lift(block))


def term_after(pb: LinearProblem, from_step: int, extra: np.ndarray | None = None
               ) -> tuple[float, float, float]:
    """(z, δ̂ °C, sd of δ̂) of the step term at ``from_step`` after the base (and ``extra``)."""
    Xw, yw = _diag._design(pb, [])
    U = stats.orthonormal_basis(Xw if extra is None else np.hstack([Xw, extra]))
    e = yw - U @ (U.T @ yw)
    t = pb.whiten(pb.lift(STEP.regressors(pb.ctx, float(from_step))))[:, 0]
    z = t - U @ (U.T @ t)
    nz2 = float(z @ z)
    if nz2 <= 0:
        return 0.0, float("nan"), float("inf")
    return float(z @ e) / np.sqrt(nz2), float(z @ e) / nz2, 1.0 / np.sqrt(nz2)


def worst_plateau(pb: LinearProblem, from_step: int) -> tuple[int, float, float]:
    """(plateau, keep, z after its free block) for the plateau that leaves the term least."""
    Xw, _ = _diag._design(pb, [])
    U0 = stats.orthonormal_basis(Xw)
    t = pb.whiten(pb.lift(STEP.regressors(pb.ctx, float(from_step))))[:, 0]
    n0 = float(np.sum((t - U0 @ (U0.T @ t)) ** 2))
    best = (-1, 2.0, 0.0)
    for s in pb.ctx.step_ids:
        B = plateau_block(pb, s)
        U = stats.orthonormal_basis(np.hstack([Xw, B]))
        keep = float(np.sum((t - U @ (U.T @ t)) ** 2)) / n0
        if keep < best[1]:
            best = (int(s), keep, term_after(pb, from_step, B)[0])
    return best


def _protocol(detail: dict) -> gp.Protocol2:
    tup = ("setpoints_c", "columns", "vib_sd_g")
    return gp.Protocol2(**{k: (tuple(v) if k in tup else v) for k, v in detail.items()})


def _outcome(d: dict) -> str:
    top = (d.get("findings") or [{}])[0]
    eff = top.get("effect")
    if eff == "not_identifiable":
        return "not separable: " + "/".join((top.get("where") or {}).get("candidates") or [])
    listed = [n for n in d.get("not_identifiable") or [] if n["effect"] == "temperature_sensor"
              and "alone" in n["why"]]
    return (eff or "none") + (" (listed: one plateau alone)" if listed else "")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--multiple", type=float, default=None, help="only cases at this multiple")
    a = ap.parse_args(argv)
    pools = load_pools(realdata_dir(a.realdata))
    diags = json.loads((a.out / "diagnoses.json").read_text())
    print("| case | × | protocol | from / plateaus | δ °C | λ exact | z term | δ̂ ± sd °C "
          "| worst plateau: keep, z after | reported |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for kp in sorted((a.out / "keys").glob("*.json")):
        key = json.loads(kp.read_text())
        if key.get("effect") != "temperature_sensor" or key["kind"] != "catalogue":
            continue
        if a.multiple is not None and key["multiple"] != a.multiple:
            continue
        proto = _protocol(key["protocol_detail"])
        sensor = draw_sensor(np.random.default_rng(key["seed"]))
        lam, _ = detect.lam_fn(proto, sensor, pools, "temperature_sensor", key["pattern"],
                               key["seed"])
        pb = build_problem(read_recording(a.out / "cases" / f"{kp.stem}.csv"))
        k0, m = key["pattern"]["from_step"], key["magnitude"]
        z, dh, sd = term_after(pb, k0)
        s, keep, z_after = worst_plateau(pb, k0)
        kind = "/".join(key["protocol"].split("/")[:2])
        print(f"| {kp.stem} | {key['multiple']:g} | {kind} | {k0} / {len(proto.setpoints_c)} "
              f"| {m:.3f} | {lam(m):.1f} | {z:.1f} | {dh:.3f} ± {sd:.3f} "
              f"| {s}: {keep:.2f}, {z_after:.1f} | {_outcome(diags[kp.stem])} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
