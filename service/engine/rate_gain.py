"""The sensor's sensitivity to the rate of die-temperature change, from the campaign's own probes.

While the die moves, package and board lag it and the output carries a term
k × dT/dt (the ``temperature_rate`` effect of docs/effects.md, k in
µg per °C/min). The soak must wait until k × rate is below the noise
(:mod:`service.engine.stability`), so k sets the soak; today it is assumed
(``gradient_lag_s``). Here it is measured from the soak probes the engine
takes anyway: at one table orientation the probe output is

    out(t) = f(T(t)) + k · dT/dt(t) + noise,

f a smooth polynomial of the die temperature T (the thermal model of the
seed paper's Eq. 12–14, cubic at most). Within one soak the die follows a
first-order approach, so dT/dt = (T∞ − T)/τ is a straight line in T and k
cannot be told from f; across soaks it can: the rate is a sawtooth in T (high
at each soak start, near zero at each end, 10 °C further on), which no cubic
follows. T and dT/dt come from :func:`stability.fit_approach` per soak (the
fitted curve, not differenced readings: differencing noisy readings would
bias k towards 0, the unsafe direction). The probes taken during a ramp count
too, with the readings' central difference as the rate (large there, so the
bias is negligible: :func:`ramp_rate_c_per_min`): the first ramp with the first
soak separates k (a trapezoid of rate in T), so k is measured during the first
soak, not after it.

Precision: with 8-sample probes (the default) a whole −40…60 °C campaign
gives σ(k) ≈ 25–30 µg per °C/min, too weak to shorten a soak; with
200-sample probes ≈ 5 (docs/engine.md, "Measured rate sensitivity").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from service.engine.stability import fit_approach

# What a sensor is assumed to have until the campaign has measured it: the catalogue's
# typical temperature_rate gain (docs/effects.md), the safe side for a new die.
PRIOR_RATE_GAIN_UG_PER_C_PER_MIN = 100.0
MIN_PROBES_PER_SOAK = 6  # fewer and the soak's approach cannot be fitted
# A campaign of at least this many soaks at one pose measures k well enough for the fit to
# correct it (200–250-sample probes: σ_k ≈ 7 µg per °C/min after three soaks, ≈ 3 after ten;
# docs/engine.md), so its first soaks may already count on that correction.
SOAKS_TO_CORRECT = 3
# The estimate is used once z·σ is at most this fraction of the prior (2σ ≤ 50 µg per °C/min).
INFORMATIVE_FRACTION = 0.5
# What the calibration's correction k̂·rate may still get wrong besides σ_k (docs/engine.md,
# "The allowance, derived"), as a fraction of the largest gain the data allow, |k̂| + z·σ: the
# package and board are only approximately a first-order lag behind the die reading, so
# k·dT/dt is only approximately the output's rate term; that error scales with the true gain.
# A judgement (a first-order lag's error over a 6-min sweep for τ ≳ 15 min is a few per cent,
# doubled and rounded up); the twin's rate effect is exactly first-order, so there it is margin.
RATE_ALLOWANCE_FRACTION = 0.1


@dataclass(frozen=True)
class SoakProbes:
    """The probes of one soak, all at one table orientation (``orientation`` names it).

    ``ramp``: taken while the chamber ramped to the step (the air not yet in its band), not
    during a soak: the die is then no first-order approach, and its rate comes from the
    readings themselves (:func:`ramp_rate_c_per_min`).
    """

    orientation: str
    t_s: np.ndarray  # (n,) probe times
    die_c: np.ndarray  # (n,) die temperature channel, °C
    out_g: np.ndarray  # (n, 3) mean output per axis, g
    ramp: bool = False

    @cached_property
    def rate(self) -> tuple[np.ndarray, np.ndarray] | None:
        """:func:`soak_rate_c_per_min` (a ramp: :func:`ramp_rate_c_per_min`) of these
        probes, computed once (the engine re-estimates k at every poll from every finished
        soak). NaN where a probe has no rate (a ramp's first and last)."""
        if self.ramp:
            return ramp_rate_c_per_min(self.t_s, self.die_c)
        return soak_rate_c_per_min(self.t_s, self.die_c)


@dataclass(frozen=True)
class RateGain:
    """k per axis (µg per °C/min) with its 1-σ uncertainty; ``n`` probes, ``soaks`` used."""

    gain_ug_per_c_per_min: np.ndarray
    sd_ug_per_c_per_min: np.ndarray
    n: int
    soaks: int

    def upper_ug_per_c_per_min(self, z: float = 2.0) -> float:
        """Largest |k| + z·σ over the axes: what the soak decision may rely on."""
        return float(np.max(np.abs(self.gain_ug_per_c_per_min) + z * self.sd_ug_per_c_per_min))


def soak_rate_c_per_min(t_s: np.ndarray, die_c: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(T, dT/dt in °C/min) of the fitted first-order approach at the probe times, or None."""
    t = np.asarray(t_s, float)
    if t.size < MIN_PROBES_PER_SOAK:
        return None
    fit = fit_approach(t, np.asarray(die_c, float))
    if not fit.ok or not math.isfinite(fit.tau_s):
        return None
    e = np.exp(-(t - t[0]) / fit.tau_s)
    temp_c = fit.t_inf_c - fit.amplitude_c * e
    return temp_c, 60.0 * fit.amplitude_c / fit.tau_s * e


def ramp_rate_c_per_min(t_s: np.ndarray, die_c: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray] | None:
    """(T, dT/dt in °C/min) during a ramp: central differences of the die readings.

    While the air ramps the die is no first-order approach (it lags a moving air), so there
    is no fitted curve to differentiate. Differencing is safe here, unlike at a soak's end:
    the rate is large (up to the ramp's 2 °C/min) against the difference's noise (two
    250-sample readings of ±0.006 °C a minute apart: ±0.01 °C/min), so the noise in the
    regressor biases k towards 0 by a part in 10⁴ (errors in variables: var(noise) / var(rate)).
    The first and last probe (one-sided differences, off by the curvature) get NaN.
    """
    t = np.asarray(t_s, float)
    temp_c = np.asarray(die_c, float)
    if t.size < MIN_PROBES_PER_SOAK or np.any(np.diff(t) <= 0):
        return None
    rate = 60.0 * np.gradient(temp_c, t)
    rate[[0, -1]] = np.nan
    return temp_c, rate


def estimate_rate_gain(soaks: list[SoakProbes]) -> RateGain | None:
    """Least-squares k shared by all soaks, with a polynomial f(T) per orientation.

    An orientation with one soak only is left out: within one approach the rate
    is a straight line in T, so that soak says nothing about k, and whatever
    of f a low-degree polynomial misses would be taken for k. The degree per
    orientation is min(3, its soaks), 3 once one of them is a ramp: a ramp and the soak
    after it cover the range between them without a gap (the first ramp and soak: from the
    ambient to the first setpoint), and over it the rate is a trapezoid in T (rising at the
    ramp's start, about the ramp rate while the die lags the air, falling linearly in T
    during the approach) that no cubic follows, so k separates from one ramp and one soak:
    k is known during the first soak. Returns None when no orientation has two segments
    or there are fewer probes than unknowns + 5.
    """
    fitted = [(s, s.rate) for s in soaks]
    fitted = [(s, tr) for s, tr in fitted if tr is not None]
    count: dict[str, int] = {}
    degree: dict[str, int] = {}
    for s, _ in fitted:
        count[s.orientation] = count.get(s.orientation, 0) + 1
        degree[s.orientation] = 3 if s.ramp else min(3, max(degree.get(s.orientation, 0),
                                                               count[s.orientation]))
    rows_t, rows_r, rows_y, rows_o = [], [], [], []
    for s, tr in fitted:
        if count[s.orientation] < 2:
            continue
        ok = np.isfinite(tr[1])
        rows_t.append(np.asarray(s.die_c, float)[ok])  # measured: precise; f(T) needs the truth
        rows_r.append(tr[1][ok])
        rows_y.append(np.asarray(s.out_g, float).reshape(-1, 3)[ok] * 1e6)
        rows_o.extend([s.orientation] * int(ok.sum()))
    if not rows_t:
        return None
    temp_c, rate, out_ug = np.concatenate(rows_t), np.concatenate(rows_r), np.vstack(rows_y)
    orient = np.array(rows_o)
    # Scaled temperature keeps the cubic columns well conditioned over −40…60 °C.
    x = (temp_c - temp_c.mean()) / max(float(np.ptp(temp_c)) / 2.0, 1.0)
    cols = []
    for o in dict.fromkeys(orient):
        mask = (orient == o).astype(float)
        cols.extend(mask * x**d for d in range(degree[o] + 1))
    cols.append(rate)
    design = np.column_stack(cols)
    n, p = design.shape
    if n < p + 5:
        return None
    coef, *_ = np.linalg.lstsq(design, out_ug, rcond=None)
    resid = out_ug - design @ coef
    s2 = np.sum(resid**2, axis=0) / (n - p)
    xtx_inv = np.linalg.pinv(design.T @ design)
    var_k = float(xtx_inv[-1, -1])
    sd = np.sqrt(s2 * var_k) if var_k > 0 else np.full(3, math.inf)
    return RateGain(coef[-1].copy(), sd, n, sum(count[o] for o in dict.fromkeys(orient)))


def rate_gain_for_decision(estimate: RateGain | None, z: float = 2.0,
                           prior_ug_per_c_per_min: float = PRIOR_RATE_GAIN_UG_PER_C_PER_MIN
                           ) -> float:
    """The k (µg per °C/min) a soak decision should use.

    Once the estimate is informative (z·σ ≤ half the prior) its upper bound
    |k̂| + z·σ, whether below the prior (the data rule the typical gain out) or
    above it (this sensor is worse than typical); before that the prior, or
    the point estimate |k̂| if that is already larger.
    """
    if estimate is None:
        return prior_ug_per_c_per_min
    hi = estimate.upper_ug_per_c_per_min(z)
    point = float(np.max(np.abs(estimate.gain_ug_per_c_per_min)))
    if is_informative(estimate, z, prior_ug_per_c_per_min):
        return hi
    return max(prior_ug_per_c_per_min, point) if math.isfinite(point) \
        else prior_ug_per_c_per_min


def is_informative(estimate: RateGain | None, z: float = 2.0,
                   prior_ug_per_c_per_min: float = PRIOR_RATE_GAIN_UG_PER_C_PER_MIN) -> bool:
    """z·σ of every axis at most half the prior: the estimate may replace the prior."""
    if estimate is None:
        return False
    sd = float(np.max(estimate.sd_ug_per_c_per_min))
    return math.isfinite(sd) and z * sd <= INFORMATIVE_FRACTION * prior_ug_per_c_per_min


def residual_rate_gain_for_decision(
        estimate: RateGain | None, z: float = 2.0,
        prior_ug_per_c_per_min: float = PRIOR_RATE_GAIN_UG_PER_C_PER_MIN,
        will_correct: bool = False) -> float:
    """The k a soak decision should use when the calibration subtracts k̂·rate from the rows.

    The rows are corrected with the campaign's k̂, so what a step measured while the die
    moved still carries is (k − k̂)·rate, at most z·σ_k·rate, plus what the correction's
    first-order model gets wrong, ``RATE_ALLOWANCE_FRACTION`` × (|k̂| + z·σ_k)·rate: per axis
    z·σ_k + that fraction, the largest over the axes. The decision holds it to a quarter of
    the step mean's noise (``stability``: the common budget), i.e. to +3 % of the held-out
    error in quadrature: the per-step bias it leaves enters the thermal fit the way the
    step mean's noise does (docs/engine.md, "The allowance, derived"). No floor: a k̂
    measured near 0 with a small σ_k leaves little to wait for, and the curvature and the
    step tolerances of the decision still hold.

    Before the estimate is informative nothing can be corrected yet, but with
    ``will_correct`` (the campaign has the soaks to come that will measure k, and the fit
    corrects every row with the final k̂ when that is informative) the rows of this soak
    will be corrected too: the residual is then at most the least precise estimate the fit
    still corrects with (z·σ = ``INFORMATIVE_FRACTION`` × prior) plus the model fraction of
    the larger of the prior and |k̂|. Without it, the uncorrected rule
    (:func:`rate_gain_for_decision`).
    """
    if estimate is not None and is_informative(estimate, z, prior_ug_per_c_per_min):
        sd = np.asarray(estimate.sd_ug_per_c_per_min, float)
        upper = np.abs(estimate.gain_ug_per_c_per_min) + z * sd  # the largest |k| per axis
        return float(np.max(z * sd + RATE_ALLOWANCE_FRACTION * upper))
    if not will_correct:
        return rate_gain_for_decision(estimate, z, prior_ug_per_c_per_min)
    worst_zsd = INFORMATIVE_FRACTION * prior_ug_per_c_per_min
    point = prior_ug_per_c_per_min
    if estimate is not None:
        k_hat = float(np.max(np.abs(estimate.gain_ug_per_c_per_min)))
        point = max(point, k_hat) if math.isfinite(k_hat) else point
    return worst_zsd + RATE_ALLOWANCE_FRACTION * (point + worst_zsd)


def correction_gain_ug_per_c_per_min(estimate: RateGain | None, z: float = 2.0
                                     ) -> np.ndarray | None:
    """k̂ per axis the calibration should subtract (times each row's die rate), or None.

    Only an informative estimate corrects: a noisy k̂ would add σ_k·rate where the
    decision, not knowing k, already waited for the rate to fall below the noise.
    """
    if not is_informative(estimate, z):
        return None
    assert estimate is not None
    return np.asarray(estimate.gain_ug_per_c_per_min, float).copy()


# --- a campaign's book of soaks, per sensor ------------------------------------------------
@dataclass(frozen=True)
class Probe:
    """One die probe: clock time (the decision's), campaign time, die channel, mean output."""

    clock_s: float
    t_s: float
    sensor_c: float
    mean_g: tuple[float, ...]


def soak_probes(pose: str, probes: list[Probe], ramp: bool = False) -> SoakProbes:
    """One soak's (``ramp``: one ramp's) probes at ``pose`` as :class:`SoakProbes`."""
    return SoakProbes(pose, np.array([p.t_s for p in probes]),
                      np.array([p.sensor_c for p in probes]),
                      np.array([p.mean_g for p in probes], float), ramp)


@dataclass
class RateGainBook:
    """Every sensor's finished soaks and ramps, from which its k is estimated.

    ``measured``: the campaign measures the rate gain (spec ``rate_gain``); otherwise
    the decision uses the spec's ``gradient_lag_s`` and the fit gets no k.
    """

    measured: bool
    n_steps: int
    soaks: dict[str, list[SoakProbes]]

    @classmethod
    def from_rows(cls, rows: list[dict[str, Any]], *, measured: bool, n_steps: int,
                  tol_c: float) -> RateGainBook:
        """The soaks of an interrupted run, from its stored probe rows (``soak_probes``)."""
        groups: dict[tuple[str, int, float, str], list[dict[str, Any]]] = {}
        for r in rows:
            groups.setdefault((r["sensor"], r["step"], r["soak_start_t_s"], r["pose"]),
                              []).append(r)
        soaks: dict[str, list[SoakProbes]] = {}
        for (serial, _, _, pose), group in groups.items():
            if len(group) >= MIN_PROBES_PER_SOAK:
                # A ramp's probes begin with the air outside the band (a soak starts once
                # the air is in it): no column needed to tell them apart.
                first = min(group, key=lambda r: r["t_s"])
                air_c, setpoint_c = first.get("chamber_c"), first.get("setpoint_c")
                ramp = (air_c is not None and setpoint_c is not None
                        and abs(air_c - setpoint_c) > tol_c)
                soaks.setdefault(serial, []).append(SoakProbes(
                    pose, np.array([r["t_s"] for r in group], float),
                    np.array([r["sensor_c"] for r in group], float),
                    np.array([[r["ax"], r["ay"], r["az"]] for r in group], float), ramp))
        return cls(measured, n_steps, soaks)

    def keep(self, pose: str, dies: dict[str, list[Probe]], ramp: bool = False) -> None:
        """Add a finished (or interrupted) soak's (``ramp``: ramp's) probes of each sensor."""
        for serial, probes in dies.items():
            if len(probes) >= MIN_PROBES_PER_SOAK:
                self.soaks.setdefault(serial, []).append(soak_probes(pose, probes, ramp))

    def estimate(self, serial: str, pose: str = "",
                 current: list[Probe] | None = None) -> RateGain | None:
        """k of one sensor from its finished soaks and the ``current`` one's probes."""
        soaks = list(self.soaks.get(serial, []))
        if current is not None and len(current) >= MIN_PROBES_PER_SOAK:
            soaks.append(soak_probes(pose, current))
        return estimate_rate_gain(soaks)

    def for_decision(self, serial: str, pose: str, current: list[Probe]) -> float | None:
        """k (µg per °C/min) for ``stability.decide``; None: the spec's ``gradient_lag_s``.

        Measured: the calibration subtracts k̂·rate, so only what the correction may get
        wrong counts (:func:`residual_rate_gain_for_decision`). The fit corrects every
        row, this soak's too, with the campaign's final k̂: a campaign with the soaks to
        measure it may soak for that correction's residual before its own estimate is
        informative (the first soak: the prior's 100 would otherwise keep it ≈ 30 min
        longer).
        """
        if not self.measured:
            return None
        return residual_rate_gain_for_decision(self.estimate(serial, pose, current),
                                               will_correct=self.n_steps >= SOAKS_TO_CORRECT)

    def provenance(self, serial: str) -> dict[str, Any]:
        """The campaign's measured rate gain of one sensor, for the fit and its provenance
        (empty when it is not measured)."""
        if not self.measured:
            return {}
        est = self.estimate(serial)
        k_hat = correction_gain_ug_per_c_per_min(est)
        return {
            "rate_gain_ug_per_c_per_min": None if k_hat is None else k_hat.tolist(),
            "rate_gain_estimate": None if est is None else {
                "gain_ug_per_c_per_min": est.gain_ug_per_c_per_min.tolist(),
                "sd_ug_per_c_per_min": est.sd_ug_per_c_per_min.tolist(),
                "probes": est.n, "soaks": est.soaks},
        }
