"""Noise shared by the readings of one plateau: measured, and injected (issue 22).

    python -m benchmarks.blind.plateau_share estimate --out OUT
    python -m benchmarks.blind.plateau_share inject --out OUT --sd-c 0,0.05,0.1 [--cases 60]
                                                    [--n-null 400] [--jobs 2]

``estimate``: for every case of a blind-benchmark directory (``OUT/cases/*.csv``) the base
model's whitened residual is split into plateau × axis means and the scatter within; the
variance of a random offset per plateau and axis, beyond what the within scatter predicts,
is fitted by maximum likelihood (:func:`plateau_variance`) and reported as θ = σ_b²/s²
(s² the within scatter) with the likelihood-ratio p of θ = 0. With the run's
``OUT/diagnoses.json`` the cases are split into flagged and unflagged, and what fired (the
findings, the scan) is listed.

``inject``: the first ``--cases`` recordings get one die-temperature error per plateau,
N(0, sd_c²), the same for every reading of the plateau (the recorded temperature columns
shifted by it: through the model's ∂output/∂T it is an offset per plateau and axis), and
are diagnosed; the false-alarm rate per sd_c is printed with its 95 % interval.
"""

from __future__ import annotations

import argparse
import json
from multiprocessing import Pool
from pathlib import Path

import numpy as np
from scipy import stats as sps
from scipy.optimize import minimize_scalar

from calibration.discrepancy import diagnose
from calibration.discrepancy.diagnose import _basis
from calibration.discrepancy.problem import build_problem
from calibration.recording import TEMPERATURE, Recording, read_recording


def plateau_variance(e: np.ndarray, U: np.ndarray, group: np.ndarray) -> dict[str, float]:
    """ML estimate of θ = σ_b²/s² of a random offset per group in e = (I − P)(ε + Z b).

    Z the group indicator (entries × groups), G = Zᵀ(I − P)Z = VΛVᵀ; d = VᵀZᵀe has
    independent entries of variance s²λ(1 + θλ). s² is the scatter outside span((I − P)Z)
    (what the groups cannot explain). Returns θ, the likelihood-ratio p of θ = 0 (½χ²₀ +
    ½χ²₁), the groups' residual rank and s².
    """
    _, g = np.unique(group, return_inverse=True)
    Z = np.zeros((e.size, int(g.max()) + 1))
    Z[np.arange(e.size), g] = 1.0
    UZ = U.T @ Z
    G = Z.T @ Z - UZ.T @ UZ
    lam, V = np.linalg.eigh(G)
    keep = lam > 1e-9 * lam.max()
    lam, V = lam[keep], V[:, keep]
    d = V.T @ (Z.T @ e)
    r = lam.size
    s2 = float((e @ e - np.sum(d**2 / lam)) / max(e.size - U.shape[1] - r, 1))
    a = d**2 / (s2 * lam)  # χ²₁ each under θ = 0

    def nll(th: float) -> float:
        v = 1.0 + th * lam
        return 0.5 * float(np.sum(np.log(v) + a / v))

    res = minimize_scalar(nll, bounds=(0.0, 1e4), method="bounded")
    th = float(res.x) if res.fun < nll(0.0) else 0.0
    lr = 2.0 * (nll(0.0) - nll(th))
    p = 0.5 * float(sps.chi2.sf(lr, 1)) if lr > 0 else 1.0
    return {"theta": th, "p": p, "rank": r, "s2": s2, "lam_med": float(np.median(lam))}


def residual_share(rec: Recording) -> dict[str, float]:
    """:func:`plateau_variance` of the base model's whitened residual, plateau × axis."""
    pb = build_problem(rec)
    U, yw = _basis(pb, [])
    U = np.asarray(U)
    e = yw - U @ (U.T @ yw)
    step = pb.ctx.steps[pb.row]
    out = plateau_variance(e, U, step * 4 + (pb.axis + 1))
    out["plateaus"] = int(np.unique(pb.ctx.steps).size)
    return out


def _fired(d: dict) -> str:
    """What made ``d`` a mismatch, as its JSON says: the findings' effects and, where the
    localised scan was significant, "scan"."""
    parts = [str(f.get("effect")) for f in d.get("findings", [])]
    if (d.get("unexplained") or {}).get("significant"):
        parts.append("scan")
    return "+".join(parts) or "other"


def estimate(out: Path) -> None:
    dj = out / "diagnoses.json"
    res = json.loads(dj.read_text()) if dj.is_file() else {}
    rows = []
    for csv in sorted((out / "cases").glob("*.csv")):
        case = csv.stem
        r = res.get(case, {})
        try:
            est = residual_share(read_recording(csv))
        except Exception as exc:  # noqa: BLE001 - a case that cannot be judged
            print(case, "skipped:", exc)
            continue
        est["case"] = case
        est["flagged"] = bool(r.get("mismatch"))
        est["fired"] = _fired(r) if r.get("mismatch") else ""
        rows.append(est)
    for flag in (True, False):
        sub = [r for r in rows if r["flagged"] == flag]
        if not sub:
            continue
        th = np.array([r["theta"] for r in sub])
        p = np.array([r["p"] for r in sub])
        print(f"{'flagged' if flag else 'unflagged'} {len(sub)}: θ median {np.median(th):.3f}, "
              f"mean {th.mean():.3f}, 90th pct {np.quantile(th, 0.9):.3f}; LR p ≤ 0.05: "
              f"{int((p <= 0.05).sum())} ({(p <= 0.05).mean():.1%}), p ≤ 0.01: "
              f"{int((p <= 0.01).sum())}")
    for r in rows:
        if r["flagged"]:
            print(f"  {r['case']} K={r['plateaus']} rank={r['rank']} θ={r['theta']:.3f} "
                  f"p={r['p']:.3g} {r['fired']}")


def shifted(rec: Recording, sd_c: float, rng: np.random.Generator) -> Recording:
    """``rec`` with one temperature error per plateau, N(0, sd_c²), on every recorded
    temperature column (what the die was is not what was recorded, by plateau)."""
    cols = {k: np.array(v, float) for k, v in rec.columns.items()}
    steps = cols["step"].astype(int)
    u, inv = np.unique(steps, return_inverse=True)
    dt = rng.normal(0.0, sd_c, u.size)[inv]
    for name in TEMPERATURE:
        if name in cols and np.isfinite(cols[name]).any():
            cols[name] = cols[name] + dt
    return Recording.from_columns(cols, path=rec.path)


_N_NULL = [400]


def _one(args: tuple[str, float, int]) -> tuple[str, float, bool, str]:
    csv, sd_c, seed = args
    rec = shifted(read_recording(csv), sd_c, np.random.default_rng(seed))
    d = json.loads(diagnose(rec, seed=seed, n_null=_N_NULL[0]).to_json())
    return Path(csv).stem, sd_c, bool(d.get("mismatch")), _fired(d) if d.get("mismatch") else ""


def _init(n_null: int) -> None:
    _N_NULL[0] = n_null


def inject(out: Path, sds: list[float], n_cases: int, n_null: int, jobs: int) -> None:
    cases = sorted((out / "cases").glob("*.csv"))[:n_cases]
    work = [(str(c), sd, 1000 * i + int(c.stem)) for i, sd in enumerate(sds) for c in cases]
    with Pool(jobs, initializer=_init, initargs=(n_null,)) as pool:
        got = pool.map(_one, work, chunksize=1)
    for sd in sds:
        sub = [g for g in got if g[1] == sd]
        k, n = sum(g[2] for g in sub), len(sub)
        lo, hi = sps.beta.ppf(0.025, k, n - k + 1) if k else 0.0, sps.beta.ppf(0.975, k + 1, n - k)
        fired = [f"{g[0]}:{g[3]}" for g in sub if g[2]]
        print(f"sd_c = {sd:g} °C: flagged {k}/{n} = {k / n:.1%} ({lo:.1%}–{hi:.1%}) {fired}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("estimate", "inject"))
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--sd-c", default="0,0.05,0.1")
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--n-null", type=int, default=400)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    if a.mode == "estimate":
        estimate(a.out)
    else:
        inject(a.out, [float(x) for x in a.sd_c.split(",")], a.cases, a.n_null, a.jobs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
