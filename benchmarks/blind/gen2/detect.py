"""Minimum detectable size on the second generator, with its own base design.

λ(m) = ‖(I − P)·y(m)/σ‖ over the three axes, where y(m) is the noise-free recording with
the effect at size m (for the temperature-channel step the recorded temperature moves, not
the output), P the projector on the base design written here — per axis the columns
(1, ref_x, ref_y, ref_z) × (1, t, t², t³), t the recorded temperature scaled to [−1, 1] —
and σ the true scatter of one capture mean (``simulate.reading_sigma_g``, correlation within
a capture included). m* is where λ reaches the value that gives 50 % power to a χ² test at
α = 0.01/15 with the effect's dof; for an outlier the per-reading χ²₃ at α/(15·N) (the
readings are not known in advance). Monotone λ(m) is bisected in log m; m* = ∞ when even
10⁴× the start size stays below.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from scipy import optimize
from scipy import stats as sps

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2 import unseen_effects as ux

ALPHA = 0.01 / 15
START = {"thermal_lag": 60.0, "temperature_sensor": 0.01, "turntable_tilt": 1.0,
         "turntable_encoder": 1.0, "vibration_rectification": 0.1}


@cache
def lambda_star(dof: int, level: float = ALPHA) -> float:
    crit = sps.chi2.isf(level, dof)
    return float(optimize.brentq(lambda lam: sps.ncx2.sf(crit, dof, lam**2) - 0.5, 1e-3, 50))


def temperature_regressor(cols: dict[str, np.ndarray]) -> np.ndarray:
    return cols["sensor_c"] if "sensor_c" in cols else cols["chamber_c"]


def residual_norm(y: np.ndarray, ref: np.ndarray, temp_c: np.ndarray,
                  sigma: np.ndarray) -> np.ndarray:
    """Whitened residual (N,3) of y after the base design, axis by axis."""
    t = (temp_c - temp_c.mean()) / max(np.ptp(temp_c) / 2, 1e-9)
    deg = min(3, len(np.unique(np.round(temp_c, 0))) - 1)
    u = np.column_stack([np.ones(len(t)), ref])
    X = np.column_stack([u * (t**p)[:, None] for p in range(deg + 1)])
    out = np.empty_like(y)
    for a in range(3):
        Xw, yw = X / sigma[:, a:a + 1], y[:, a] / sigma[:, a]
        beta = np.linalg.lstsq(Xw, yw, rcond=None)[0]
        out[:, a] = yw - Xw @ beta
    return out


def lam_fn(proto, sensor, pools, eid: str, pat: dict, seed: int):
    sc0 = sim.scene(proto, None, 0.0, pat, seed)
    sigma = sim.reading_sigma_g(proto, pools, sc0)

    def lam(m: float, per_row: bool = False):
        sc = sim.scene(proto, eid, m, pat, seed)
        y = sim.noise_free_output(sensor, sc, eid, m, pat)
        temp = temperature_regressor(sim.recorded_temperature_c(sc, proto, eid, m, pat))
        r = residual_norm(y, sc.ref_g, temp, sigma)
        return np.sqrt(np.sum(r**2, axis=1)) if per_row else float(np.sqrt(np.sum(r**2)))
    return lam, len(sc0.t_s)


def minimum_detectable(proto, sensor, pools, eid: str, pat: dict, seed: int) -> float:
    lam, n = lam_fn(proto, sensor, pools, eid, pat, seed)
    if eid == "outlier":
        target = lambda_star(3, ALPHA / n)
        rows = pat["rows"]

        def f(m: float) -> float:
            return float(np.max(lam(m, per_row=True)[rows]))
    else:
        target = lambda_star({**fx.DOF, **ux.DOF}[eid])
        f = lam
    lo = START.get(eid, 0.1)
    if f(lo) >= target:
        return lo
    hi = lo
    for _ in range(14):
        hi *= 2.0
        if f(hi) >= target:
            break
    else:
        return float("inf")
    return float(np.exp(optimize.brentq(lambda x: f(float(np.exp(x))) - target,
                                        np.log(hi / 2), np.log(hi), xtol=1e-3)))
