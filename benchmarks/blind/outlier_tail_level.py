"""The outlier test's level on readings with a mild Student-t tail, with and without the gate.

    python -m benchmarks.blind.outlier_tail_level [--readings 150] [--recordings 400] [--n-null 200]
        [--estimator quantiles|mle]

Recordings of N readings whose three entries share one Student-t scale (ν = 20, 40, or
Gaussian); each recording's ν is read by ``stats.reading_tail_dof`` at a margin of 2
standard errors (the gate) and at 0 (the point estimate, ``stats.NULL_TAIL_Z``, what
``diagnose`` uses), and the max over readings is scored against ``stats.row_stats``' null
with that ν. Prints, per tail and margin, the share of recordings at p ≤ 5 % and ≤ 1 % and
the share given a finite ν (docs/benchmarks.md, "False alarms of the second generator's
nulls, test by test"). ``--estimator mle`` reads the point estimate (margin 0) by
:func:`tail_dof_mle` instead, a censored maximum likelihood measured and not kept
(docs/benchmarks.md, "The outlier null's tail by maximum likelihood").
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.stats as sps
from scipy.optimize import minimize

from calibration.discrepancy import stats

# The candidate's censoring: the largest max(stats.TAIL_OUTLIERS, CENSOR_SHARE·n) readings
# enter the likelihood only as "at least this large".
CENSOR_SHARE = 0.02


def tail_dof_mle(t_row: np.ndarray, g: int) -> float:
    """ν of the per-reading statistic's g·F(g, ν) tail at its maximum likelihood, with a free
    scale and the largest readings right-censored; ∞ at stats.TAIL_DOF_MAX (the candidate for
    ``stats.reading_tail_dof`` at margin 0, measured and not kept)."""
    t = np.sort(np.asarray(t_row, float)[np.isfinite(t_row)])
    n = t.size
    if n < stats.TAIL_MIN_READINGS or g < 1:
        return np.inf
    m = max(stats.TAIL_OUTLIERS, int(np.ceil(CENSOR_SHARE * n)))
    body, cut = np.maximum(t[: n - m], 1e-300), float(t[n - m - 1])

    def nll(theta: np.ndarray) -> float:
        scale, nu = float(np.exp(theta[0])) * g, float(np.exp(theta[1]))
        ll = float(np.sum(sps.f.logpdf(body / scale, g, nu))) - body.size * np.log(scale)
        return -(ll + m * float(sps.f.logsf(cut / scale, g, nu)))

    c0 = float(np.log(np.median(t) / (g * sps.f.median(g, 50.0))))
    bounds = [(c0 - 3.0, c0 + 3.0), (np.log(stats.TAIL_DOF_MIN), np.log(stats.TAIL_DOF_MAX))]
    best = min((minimize(nll, np.array([c0, np.log(nu0)]), method="L-BFGS-B", bounds=bounds)
                for nu0 in (10.0, 100.0, 1000.0)), key=lambda r: float(r.fun))
    nu = float(np.exp(best.x[1]))
    return np.inf if nu >= 0.99 * stats.TAIL_DOF_MAX else nu


def level(z_se: float, nu_true: float, n: int, recordings: int, n_null: int,
          seed: int = 21, estimator: str = "quantiles") -> tuple[float, float, float]:
    """(share at p ≤ 0.05, share at p ≤ 0.01, share with a finite ν) of ``recordings``."""
    rng = np.random.default_rng(seed)
    g = 3
    row = np.repeat(np.arange(n), g)
    U = np.zeros((n * g, 0))
    ps, finite = [], 0
    for _ in range(recordings):
        w = (np.sqrt(nu_true / rng.chisquare(nu_true, n)) if np.isfinite(nu_true)
             else np.ones(n))
        e = rng.standard_normal(n * g) * w[row]
        s = float(stats.robust_scale(e[:, None], 1.0)[0])
        t, _, _ = stats.row_stats(U, e, np.zeros((n * g, 1)), row, n, s, np.ones(1), set())
        nu = (tail_dof_mle(t, g) if estimator == "mle" and z_se <= 0
              else stats.reading_tail_dof(t, g, z_se))
        finite += bool(np.isfinite(nu))
        E = rng.standard_normal((n * g, n_null))
        _, tn, _ = stats.row_stats(U, e, E, row, n, s, stats.robust_scale(E, 1.0), set(),
                                   None, nu, rng)
        ps.append((1 + np.sum(tn >= t.max())) / (n_null + 1))
    p = np.array(ps)
    return float(np.mean(p <= 0.05)), float(np.mean(p <= 0.01)), finite / recordings


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--readings", type=int, default=150)
    ap.add_argument("--recordings", type=int, default=400)
    ap.add_argument("--n-null", type=int, default=200)
    ap.add_argument("--estimator", choices=("quantiles", "mle"), default="quantiles",
                    help="the point estimate's (margin 0) estimator")
    a = ap.parse_args(argv)
    print("| readings' tail | margin (standard errors) | p ≤ 5 % | p ≤ 1 % | ν finite |")
    print("|---|---|---|---|---|")
    for nu_true in (40.0, 20.0, np.inf):
        for z in (stats.TAIL_Z, stats.NULL_TAIL_Z):
            r5, r1, fin = level(z, nu_true, a.readings, a.recordings, a.n_null,
                                estimator=a.estimator)
            name = f"Student-t ν = {nu_true:g}" if np.isfinite(nu_true) else "Gaussian"
            print(f"| {name} | {z:g} | {100 * r5:.2f} % | {100 * r1:.2f} % | "
                  f"{100 * fin:.1f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
