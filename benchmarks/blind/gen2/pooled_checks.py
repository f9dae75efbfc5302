"""The physics checks' F tests on the second generator: one pooled noise scale against
forms that read the noise by plateau or by reading (issue 22).

    python -m benchmarks.blind.gen2.pooled_checks --cases OUT/cases [--first N] [--out J]
                                                  [--wild]
    python -m benchmarks.blind.gen2.pooled_checks --cases OUT/cases --trace [--out J]

Several physics checks (``CatalogueEffect.misses`` and ``shape_after_turn``) judged a score
with ``structure.log_p``, an F test with one noise scale for the whole recording. The
second generator whitens a recording's quiet plateaus to ~0.9–1.0 of unit variance and its
vibrating ones to ~0.7–0.8, which ran the channel step's time check above its level
(docs/benchmarks.md, "Three separable cases withheld by a physics check"). This measures
the other checks' levels the same way, on the same columns, in each form:

* ``pooled``: ``structure.log_p``;
* ``by reading``: ``structure.log_p_by_reading`` (the channel step's check);
* ``by reading, basis``: the same on an orthonormal basis of the columns (their rank as k);
  ``…, F(Q)``: its Q judged as (Q/k) / ((n − Q)/(n − k)), n the readings;
* ``per-plateau scale``: the pooled F after scaling each plateau by its own residual scale
  (``structure.log_p_by_plateau``'s arithmetic, computed here on its own);
* ``sign flips``: Q against its own law under one random sign per reading (B = 1999);
* ``wild bootstrap, re-projected`` (``--wild``, slow): Q against replicates
  (I − UUᵀ)(ε_b ∘ ẽ), Q recomputed on each (B = 499).

Without ``--trace`` (on nulls: ``gen2.run --only null``'s cases): per case, the check's
term is added to the base model (no effect is present, so its physics holds and the check
rejects with probability α under a calibrated test) and the check's columns are tested:

* ``rate_gain``: ``temperature_rate.gain_differs_between_plateaus`` (the rate term);
* ``visits``: ``structure.visits_differ`` (the input-only check; the a², a³ term, every
  revisited direction in reference mode);
* ``dir_offsets``: ``scale_nonlinearity.direction_offsets_needed`` (a², a³ term);
* ``dir_offsets_products``: the same after the products of two axes' inputs
  (``cross_coupling.shape_after_turn``'s first test);
* ``sweep_offsets``: ``CrossCoupling._offset_per_sweep`` (after the products);
* ``turn_along``: ``TurntableGeometry.misses``' along-the-reference test (free turn per pose).

With ``--trace`` (e.g. a catalogue run's cases): ``diagnose`` is run as the benchmark runs
it and every ``log_p`` (and ``log_p_by_plateau``) call is recorded with its caller and
every form's p, so the checks' decisions on the cases where they ran can be compared.

Prints, per check, the cases tested and the share at p ≤ 0.05 and ≤ 0.005 (95 %
Clopper–Pearson) for each form.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy import samples as samples_mod
from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID, channel_glitch, scale_nonlinearity, structure
from calibration.discrepancy.problem import build_problem
from calibration.recording import read_recording

dmod = importlib.import_module("calibration.discrepancy.diagnose")
LOG10 = np.log(10.0)
_POOLED = structure.log_p
_BY_PLATEAU = getattr(structure, "log_p_by_plateau", None)  # absent before issue 22's change
_PATCHED = (structure, scale_nonlinearity, channel_glitch)


class Recorder:
    """Replaces ``log_p`` (and ``log_p_by_plateau``, where the code has it) in the modules
    that call them: returns what the replaced function returns (so the caller's decision is
    unchanged) and records every form with the calling function. Calls made inside a
    recorded call are not recorded."""

    def __init__(self, pb: Any) -> None:
        self.pb = pb
        self.calls: list[dict[str, Any]] = []
        self.busy = False

    def pooled(self, U: np.ndarray, e: np.ndarray, Xw: np.ndarray) -> tuple[float, int]:
        return self._record(_POOLED, U, e, Xw)

    def by_plateau(self, pb: Any, U: np.ndarray, e: np.ndarray, Xw: np.ndarray
                   ) -> tuple[float, int]:
        return self._record(_BY_PLATEAU, U, e, Xw, pb)

    def _record(self, fn: Any, U: np.ndarray, e: np.ndarray, Xw: np.ndarray, *pb: Any
                ) -> tuple[float, int]:
        if self.busy:
            return fn(*pb, U, e, Xw)
        self.busy = True
        try:
            out = fn(*pb, U, e, Xw)
            lp, k = _POOLED(U, e, Xw)
            call: dict[str, Any] = {"caller": inspect.stack()[2].function, "k": k,
                                    "n_read": int(np.unique(self.pb.row).size),
                                    "used": fn.__name__, "log10_p": lp / LOG10}
            for name, form in FORMS.items():
                call[name] = (form(self.pb, U, e, Xw)[0] if k else 0.0) / LOG10
        finally:
            self.busy = False
        self.calls.append(call)
        return out


def _shares(pb: Any, U: Any, e: np.ndarray, Xw: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, int, int] | None:
    """The readings' shares G and the score s of ``Xw``'s orthonormal basis after U
    (structure.reading_shares), its dof k and the readings n; None where k = 0 or n ≤ k + 1."""
    Z = stats.orthonormal_basis(stats.project_out(U, Xw), 1e-6)
    k = Z.shape[1]
    n = int(np.unique(pb.row).size)
    if k == 0 or n <= k + 1:
        return None
    G, s = structure.reading_shares(pb, U, e, Z)
    return G, s, k, n


def by_reading_f(pb: Any, U: Any, e: np.ndarray, Xw: np.ndarray, beta: bool = True
                 ) -> tuple[float, int]:
    """``log_p_by_reading``'s Q = sᵀV⁻¹s judged as F = (Q/k) / ((n − Q)/(n − k)), n the
    readings: under sign flips Q = εᵀPε with εᵀε = n (P the projection on the readings'
    score shares), whose Gaussian analogue is that F."""
    shares = _shares(pb, U, e, Xw)
    if shares is None:
        return 0.0, 0
    G, s, k, n = shares
    q = float(s @ np.linalg.lstsq(G.T @ G, s, rcond=None)[0])
    f = (q / k) / max((n - q) / (n - k), 1e-300) if beta else q / k
    return float(stats.f_logsf(f, k, n - k)), k


def by_sign_flips(pb: Any, U: Any, e: np.ndarray, Xw: np.ndarray, n_flip: int = 1999
                  ) -> tuple[float, int]:
    """``log_p_by_reading``'s Q = sᵀV⁻¹s (Z an orthonormal basis of the columns after U)
    against its own sign-flip law, one sign per reading: Q_b = ‖VỠ½ Gᵀε_b‖² (G the
    readings' shares of Zᵀẽ), p = (1 + #{Q_b ≥ Q}) / (B + 1)."""
    shares = _shares(pb, U, e, Xw)
    if shares is None:
        return 0.0, 0
    G, s, k, n = shares
    G = G[np.any(G != 0, axis=1)]
    Qg = stats.orthonormal_basis(G, 1e-9)  # P = G V⁻¹ Gᵀ = Qg Qgᵀ
    q = float(s @ np.linalg.lstsq(G.T @ G, s, rcond=None)[0])
    rng = np.random.default_rng(20261127)
    eps = rng.choice((-1.0, 1.0), size=(G.shape[0], n_flip))
    qb = np.sum((Qg.T @ eps) ** 2, axis=0)
    return float(np.log((1 + np.sum(qb >= q * (1 - 1e-12))) / (n_flip + 1))), k


def _q_by_reading(pb: Any, U: Any, Z: np.ndarray, e: np.ndarray, h: np.ndarray) -> float:
    et = e / np.sqrt(1.0 - np.minimum(h, stats.LEVERAGE_MAX))
    G = np.zeros((int(pb.row.max()) + 1, Z.shape[1]))
    np.add.at(G, pb.row, Z * et[:, None])
    s = Z.T @ e
    return float(s @ np.linalg.lstsq(G.T @ G, s, rcond=None)[0])


def by_wild_bootstrap(pb: Any, U: Any, e: np.ndarray, Xw: np.ndarray, n_boot: int = 499
                      ) -> tuple[float, int]:
    """Q = sᵀV⁻¹s against a wild bootstrap that re-projects: e_b = (I − UUᵀ)(ε_b ∘ ẽ), one
    sign per reading, Q recomputed (its V too) on each; p = (1 + #{Q_b ≥ Q}) / (B + 1)."""
    Z = stats.orthonormal_basis(stats.project_out(U, Xw), 1e-6)
    k = Z.shape[1]
    n = int(np.unique(pb.row).size)
    if k == 0 or n <= k + 1:
        return 0.0, 0
    h = stats.leverage(U)
    q = _q_by_reading(pb, U, Z, e, h)
    et = e / np.sqrt(1.0 - np.minimum(h, stats.LEVERAGE_MAX))
    rng = np.random.default_rng(20261127)
    eps = rng.choice((-1.0, 1.0), size=(int(pb.row.max()) + 1, n_boot))[pb.row]
    E = eps * et[:, None]
    E -= U @ (U.T @ E)
    qb = np.array([_q_by_reading(pb, U, Z, E[:, b], h) for b in range(n_boot)])
    return float(np.log((1 + np.sum(qb >= q * (1 - 1e-12))) / (n_boot + 1))), k


def _install(rec: Recorder) -> None:
    for mod in _PATCHED:
        mod.log_p = rec.pooled
        if hasattr(mod, "log_p_by_plateau"):
            mod.log_p_by_plateau = rec.by_plateau


def _uninstall() -> None:
    for mod in _PATCHED:
        mod.log_p = _POOLED
        if hasattr(mod, "log_p_by_plateau"):
            mod.log_p_by_plateau = _BY_PLATEAU





FORMS = {"log10_p_by_reading": structure.log_p_by_reading,
         "log10_p_by_reading_basis": lambda *a: by_reading_f(*a, beta=False),
         "log10_p_by_reading_f": by_reading_f,
         "log10_p_by_plateau": structure.log_p_by_plateau,
         "log10_p_sign_flips": by_sign_flips}


def problem(csv_path: Path) -> Any:
    """``diagnose``'s linear problem of one case (capture means for raw samples)."""
    rec = read_recording(csv_path)
    means = samples_mod.is_raw_samples(rec)
    if means:
        rec = samples_mod.position_means(rec)
    return build_problem(rec, capture_means=means)


def _with_term(pb: Any, effect_id: str, theta: float) -> tuple[np.ndarray, np.ndarray]:
    """Basis and residual of the base model plus one catalogue term."""
    X = pb.lift(BY_ID[effect_id].regressors(pb.ctx, theta))
    Xw = np.hstack([pb.X0, X]) * pb.w[:, None]
    U = stats.orthonormal_basis(Xw)
    yw = pb.y * pb.w
    return U, yw - U @ (U.T @ yw)


def null_case(csv_path: Path) -> dict[str, Any]:
    """Both forms' log10 p of each check on one null case (see the module's docstring)."""
    from calibration.discrepancy.effects.temperature_rate import gain_differs_between_plateaus

    pb = problem(csv_path)
    ctx = pb.ctx
    out: dict[str, Any] = {"case": csv_path.stem, "mode": pb.mode, "m": int(pb.m)}
    if 8 * pb.m * (pb.X0.shape[1] + 60) > stats.TALL_BYTES:
        out["skipped"] = "tall"
        return out
    rec = Recorder(pb)
    _install(rec)
    try:
        def run(name: str, effect_id: str, theta: float, fn: Any) -> None:
            if not BY_ID[effect_id].identifiable(ctx)[0]:
                return
            n0 = len(rec.calls)
            U, e = _with_term(pb, effect_id, theta)
            fn(U, e)
            got = [c for c in rec.calls[n0:] if c["k"]]
            if got:
                out[name] = got[-1]

        all_axes = ["x", "y", "z"]
        run("rate_gain", "temperature_rate", 0.0,
            lambda U, e: gain_differs_between_plateaus(pb, U, e, all_axes, 1.0))
        run("visits", "scale_nonlinearity", 0.0,
            lambda U, e: structure.visits_differ(pb, U, e, [], all_axes, 1.0))
        run("dir_offsets", "scale_nonlinearity", 0.0,
            lambda U, e: scale_nonlinearity.direction_offsets_needed(
                pb, U, e, (0, 1, 2), 1.0, "own-axis a² and a³ terms"))
        run("dir_offsets_products", "cross_coupling", 0.0,
            lambda U, e: scale_nonlinearity.direction_offsets_needed(
                pb, U, e, (0, 1, 2), 1.0, "products"))
        run("sweep_offsets", "cross_coupling", 0.0,
            lambda U, e: BY_ID["cross_coupling"]._offset_per_sweep(pb, U, e, 1.0))
        run("turn_along", "turntable_geometry", float("nan"),
            lambda U, e: BY_ID["turntable_geometry"].misses(
                pb, U, e, float("nan"), {}, all_axes, 1e-300))
    finally:
        _uninstall()
    return out


def trace_case(csv_path: Path) -> dict[str, Any]:
    """``diagnose`` of one case with every ``log_p`` call recorded (both forms)."""
    pb_box: dict[str, Any] = {}
    orig_build = dmod.build_problem

    def build(*a: Any, **k: Any) -> Any:
        pb = orig_build(*a, **k)
        pb_box["pb"] = pb
        rec.pb = pb
        return pb

    rec = Recorder(None)
    _install(rec)
    dmod.build_problem = build
    try:
        d = dmod.diagnose(read_recording(csv_path), seed=int(csv_path.stem))
    finally:
        dmod.build_problem = orig_build
        _uninstall()
    return {"case": csv_path.stem, "mismatch": bool(d.mismatch),
            "findings": [f.effect for f in d.findings], "calls": rec.calls}


def _rate(n: int, of: int) -> str:
    lo, hi = clopper_pearson(n, of)
    return f"{n}/{of} = {100 * n / max(of, 1):.1f} % ({100 * lo:.1f}–{100 * hi:.1f})"


def summary(rows: list[dict[str, Any]]) -> str:
    """Per check: the share of p ≤ 0.05 and ≤ 0.005, pooled and by reading."""
    by: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        for k, v in r.items():
            if isinstance(v, dict) and "log10_p" in v:
                by.setdefault(k, []).append(v)
        for c in r.get("calls", []):
            if c["k"]:
                by.setdefault(c["caller"], []).append(c)
    forms = {"pooled": "log10_p", "by reading": "log10_p_by_reading",
             "by reading, basis": "log10_p_by_reading_basis",
             "by reading, basis, F(Q)": "log10_p_by_reading_f",
             "per-plateau scale": "log10_p_by_plateau",
             "sign flips (B = 1999)": "log10_p_sign_flips",
             "wild bootstrap, re-projected (B = 499)": "log10_p_wild"}
    lines = ["| check | form | tested | p ≤ 0.05 | p ≤ 0.005 | median k / readings |",
             "|---|---|---|---|---|---|"]
    for k in sorted(by):
        for name, key in forms.items():
            if not all(key in c for c in by[k]):
                continue
            x = np.array([c[key] for c in by[k]])
            n = x.size
            kk = np.median([c["k"] for c in by[k]])
            nr = np.median([c.get("n_read", 0) for c in by[k]])
            lines.append(f"| {k} | {name} | {n} | {_rate(int(np.sum(x <= np.log10(0.05))), n)} | "
                         f"{_rate(int(np.sum(x <= np.log10(0.005))), n)} | {kk:.0f} / {nr:.0f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=Path, required=True)
    ap.add_argument("--trace", action="store_true")
    ap.add_argument("--wild", action="store_true")
    ap.add_argument("--only", default=None)
    ap.add_argument("--first", type=int, default=None)
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    if a.wild:
        FORMS["log10_p_wild"] = by_wild_bootstrap
    paths = sorted(a.cases.glob("*.csv"))
    if a.only:
        paths = [p for p in paths if p.stem in set(a.only.split(","))]
    if a.first:
        paths = paths[: a.first]
    rows = []
    for i, p in enumerate(paths, 1):
        try:
            rows.append(trace_case(p) if a.trace else null_case(p))
        except Exception as exc:  # a crash is a result too
            rows.append({"case": p.stem, "error": f"{type(exc).__name__}: {exc}"})
        if i % 50 == 0:
            print(f"  {i}/{len(paths)}", file=sys.stderr)
    if a.out:
        a.out.write_text(json.dumps(rows, default=float))
    print(summary(rows))
    errs = [r for r in rows if "error" in r]
    if errs:
        print(f"\n{len(errs)} errors, e.g. {errs[0]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
