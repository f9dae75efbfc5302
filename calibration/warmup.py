"""Warm-ups calibrated as far as they go: each axis' bias change with temperature.

A board kept still while it warms (PX4's and ArduPilot's thermal calibration logs)
shows one orientation, or a few, at a continuously changing temperature. Gravity's
projection on each axis is constant per orientation but unknown (no reference, too
few orientations for Eq. 3), so what the data identify is the *change* of each
axis' bias with temperature. Per axis ``a`` and capture ``i`` (orientation ``o``):

    raw_a,i = G_a,o + Σ_{j=1..d} c_a,j · x_i^j,    x = (T_i − centre_c) / scale_c

fitted by linear least squares to the capture means (:mod:`calibration.captures`),
each at its own mean temperature. The model stores ``b_a(T) = Σ_{j≥1} c_a,j x^j``
(zero at ``centre_c``: the bias is referred to that temperature) as the SFEM bias
polynomial (Eq. 8); scale, non-orthogonality and misalignment are held at nominal
and the model file says so (``fitted``/``held``). With 2 or more orientations, what
they determine absolutely (±z: the z bias and scale) replaces that:
:mod:`calibration.warmup_absolute`.

The degree d (0 … 3) is chosen by held-out error (:func:`_folds`): the captures'
temperature span is cut into equal blocks (:data:`HOLDOUT_BLOCKS`, none narrower than
:data:`DISTINCT_C`); the interior blocks are alternately fitted and held out (then the
other way round) and the two end blocks are always fitted, so a held-out capture is
predicted from fitted ones on both sides of its temperature: an interpolation, as a
compensation inside the valid range is. (Blocks of *time* left out the hot end of a
warm-up whole, so every degree above 1 was judged on an extrapolation the
compensation never makes; and a warm-up that rests, then heats, has its whole
temperature change in one or two time blocks.) Whether the bias changes at all is
judged first: a higher degree is preferred when it lowers the held-out squared error,
summed over the three axes, by more than :data:`MIN_GAIN` and by more than that gain's
standard error counted over the temperature blocks (:func:`_beats`): a gain within its
own standard error is no evidence (:func:`_choose_degree`). Once a change is established
so (a degree above 0, or a rate term below), the model of it is chosen among all models
of degree ≥ 1, with and without a rate term, by held-out error alone: the simplest
within :data:`MIN_GAIN` of the lowest (:func:`_choose_model`).
One model for the three axes, chosen on their sum (one axis' held-out error alone is too
noisy to choose a degree and a rate gain by); whether each axis changes at all is that
axis' own question, by the same test on its own held-out error: an axis whose held-out
squared error the model does not lower beyond that gain's standard error keeps no change
(its bias held), and one whose error a simpler model does no worse on takes the simpler
(:func:`_axis_choices`). The valid range is the span of the data's temperatures.

A rate term ``k_a(T) · dT/dt`` joins the model where the captures identify it and
held-out error prefers it. It stands for two physical things: a part whose bias
depends on how fast its die changes temperature (the ``temperature_rate`` effect,
docs/effects.md: a constant k), and a temperature channel that lags the die by τ (a
first-order lag: die = channel + τ·dT/dt exactly, so b(T_die) ≈ b(T_channel) +
b'(T)·τ·dT/dt, a gain that follows the bias slope: a polynomial of degree ≤ d − 1 in
x). Identified (:func:`_rate_check`) where dT/dt is not a function of T over the
captures: the part of it left after projecting out the orientations' constants and
the polynomial in T holds at least :data:`RATE_MIN_SHARE` of its sum of squares and is
resolved above dT/dt's noise (:data:`RATE_NOISE_SHARE`). A heating and a cooling pass
the same temperatures at opposite rates; a rest and then a heating (the inclinometer
log of issue 20) have zero and fast rates at one temperature; a monotone warm-up at a
steady or exponential rate has dT/dt ≈ f(T), any polynomial absorbs k·dT/dt, and none
is tried. The gain's degree m (0 … d − 1) is chosen with d by held-out error, simplest
first; with no change established at degree 0 the term is kept only when it lowers the
held-out squared error beyond that gain's standard error (:func:`_rate_beats`, as a
degree must), otherwise it is one of the models :func:`_choose_model` weighs. dT/dt is the
derivative of a local parabola of the capture temperatures
(:func:`calibration.temperature_conditioning.temperature_rate_c_per_min`) over the
shortest window whose noise, for this channel's noise and quantum, is small against
the rate it must resolve (:func:`calibration.temperature_conditioning.rate_window_s`);
the window is stored with the term, the same at calibrate and compensate.

Held-out error chooses among functions of temperature; it cannot say that none of them
explains the data. A board that tilts or settles, or a bias that drifts with time, leaves
the capture means scattered far beyond a capture mean's own noise whatever the degree
(:mod:`calibration.warmup_scatter`). At degree 0 (no rate term) that is refused: "no
change with temperature above the noise" would be a confident wrong answer. At a higher
degree the model is kept and its notes and the report say how much wander it leaves
(``unexplained_mg``).
"""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats as sp_stats

from calibration import sfem
from calibration.captures import CAPTURE_BLOCK_S
from calibration.gate import (
    BIAS_TEMPCO_MAX_G_PER_C,
    GateRefusal,
    Orientations,
    bias_slope_g_per_c,
    check_warmup_residuals,
)
from calibration.recording import Recording
from calibration.temperature_conditioning import (
    CaptureTemperatureNoise,
    rate_window_s,
    temperature_rate_c_per_min,
)
from calibration.thermal import ThermalModel
from calibration.warmup_absolute import AbsoluteFit, absolute_part, fitted_note, held_note
from calibration.warmup_scatter import scatter_check

MAX_DEGREE = 3
# Held-out error is judged on this many equal temperature blocks of the captures' span
# (fewer where a block would be narrower than DISTINCT_C; at least 4: two ends that are
# always fitted and one interior block in each fold).
HOLDOUT_BLOCKS = 20
MIN_HOLDOUT_BLOCKS = 4
# Capture temperatures closer than this are one temperature when bounding the degree.
DISTINCT_C = 0.25
# A degree must lower the held-out RMS by more than this fraction (and by more than the
# gain's standard error, _beats) to be preferred to a lower one; the rate term's choice
# uses this fraction alone.
MIN_GAIN = 0.005
# ... unless the means of the held-out temperature blocks are better predicted beyond
# chance (a one-sided Wilcoxon signed-rank test over the blocks at the verdicts' level,
# 0.5 %): then the gain is evidence whatever its share of the held-out RMS. A log whose
# rows are single samples (unaveraged, or a time unit read wrong) has held-out errors
# dominated by each row's white noise: the inclinometer log of issue 20 read with its time
# in ms as s has a bias change of z a 0.4 % share of that RMS over 100,000 rows, and
# MIN_GAIN alone answered "no change with temperature above the noise". A block's mean
# averages that noise away and keeps the change. Ranks, not a t test of the blocks' gains:
# a real change's gain is the square of the local bias change, near zero in the middle
# blocks of a linear one and large at the ends, a spread that hides it from a t test (a
# 10 mg change over 18,000 rows of 20 mg noise, 20 standard errors of its slope, reached
# t = 3.5–4.9 against 3.65); under no change a higher degree's gain in a block is as
# likely negative as positive, or more so (it fits the fitted blocks' noise), so the
# level holds: 1 of 300 such nulls reached 1 %.
STRONG_GAIN_P = 0.005
# A rate term is tried only where dT/dt is not a function of T over the captures
# (:func:`_rate_check`): the part of it left after projecting out the orientations'
# constants and the polynomial in T of the highest degree judged must be resolved
# (RATE_NOISE_SHARE) and hold at least this share of the rate column's sum of squares.
# What identifies the gain k is that residual's size in °C/min, not its share: k's
# standard error is σ_bias / √Σ residual², whatever part of Σ rate² the polynomial in T
# took. A fast heating at a near-steady rate leaves a small share of a large rate: a ramp
# at 2 °C/min read by a channel lagging 16.6 s (gen2 w1001) leaves 0.7 %, 0.17 °C/min RMS,
# several times dT/dt's noise, and k·dT/dt there is a bias the polynomial cannot take.
# Since the residual's resolution is RATE_NOISE_SHARE's test and the gain's worth the
# held-out error's (_rate_beats, _choose_model: a gain within its own standard error is
# refused), this share only guards the design's conditioning: 1/share is the variance
# inflation of k against a rate uncorrelated with T, at most 1000.
RATE_MIN_SHARE = 0.001
# The same share for each further column of the gain, dT/dt·x^j, j ≥ 1
# (:func:`_gain_degree_identified`). These have no resolution test, so the share is
# their only guard: at RATE_MIN_SHARE a heating and a 5-min cooling (a constant gain of
# 40 µg/(°C/min)) got a degree-2 gain ranging −52 … +40 over the span, within the
# held-out error; at 1 % the constant.
GAIN_MIN_SHARE = 0.01
# dT/dt is read over the shortest window (temperature_conditioning.RATE_WINDOWS_S) whose
# noise is at most this share of that residual rate's RMS: errors in dT/dt then shrink the
# fitted gain by at most 1 % (their variance over the residual's).
RATE_NOISE_SHARE = 0.1
HELD_WHY = {
    "scale": "held at 1: one orientation per axis cannot separate scale from gravity's "
             "unknown projection",
    "angle": "held at 0: a rotation of the sensor frame is invisible without reference "
             "directions or many orientations",
}
BIAS_NOTE = ("fitted: its change with temperature, referred to centre_c (the constant part "
             "is gravity's unknown projection and is not identified; a change of scale "
             "with temperature is included as seen at the recorded orientation(s))")


@dataclass
class WarmupFit:
    model: ThermalModel
    report: dict[str, Any]
    # the orientations fitted: the gate's clusters, those a drift connects joined
    orientations: Orientations
    notes: list[str] = field(default_factory=list)
    absolute: AbsoluteFit | None = None  # what 2+ orientations determine absolutely
    joined_note: str | None = None  # how they were joined (None: as the gate found them)


def fit_warmup(captures: Recording, orientations: Orientations,
               span_c: tuple[float, float] | None = None,
               max_degree: int = MAX_DEGREE, g_local: float = 1.0,
               rebuild_noise: Callable[[float], float] | None = None,
               own_noise: CaptureTemperatureNoise | None = None) -> WarmupFit:
    """Fit each axis' bias change with temperature (module docstring) to capture means.

    The warm-up solver behind :func:`calibration.fitting.fit`: to calibrate a
    recording, call that.

    ``span_c``: the temperature span of the data as read (the raw rows'); default the
    captures'. ``g_local``: |g| for a norm-mode absolute fit of 2 or more orientations
    (:func:`absolute_part`). ``own_noise``: what the raw samples say of each capture mean's
    temperature noise (:func:`calibration.temperature_conditioning.
    capture_temperature_noise`), for the rate check (:func:`_rate_check`); None: the
    capture means' second differences. Raises :class:`GateRefusal` when the temperature
    does not change enough to see anything.
    """
    T = captures.temperature_c()
    raw = captures.raw_g
    lo, hi = span_c if span_c is not None else (float(np.min(T)), float(np.max(T)))
    n_temps = _count_distinct(T, DISTINCT_C)
    top = min(max_degree, n_temps - 1)
    if top < 1:
        raise GateRefusal(
            f"{orientations.count} distinct orientation(s) ({orientations.names()}) and "
            f"capture temperatures spanning {np.ptp(T):.2f} °C ({np.min(T):.2f} .. "
            f"{np.max(T):.2f} °C): too little to see a change of bias with temperature; "
            f"record while the temperature changes by a few °C, or at least 10 distinct "
            f"orientations per step for an SFEM fit")
    orientations, joined_note = _joined_by_drift(captures.t_s, T, raw, orientations)
    _check_connected(T, orientations)
    centre = 0.5 * (lo + hi)
    scale = max(0.5 * (hi - lo), 1.0)
    x = (T - centre) / scale
    labels = orientations.labels
    folds = _folds(T)
    errors = [_heldout_errors_g(x, labels, raw, folds, d) for d in range(top + 1)]
    heldout = [_rms(e) for e, _ in errors]
    totals = [float(np.sqrt(np.mean(h ** 2))) for h in heldout]
    judged = [d for d in range(top + 1) if np.isfinite(totals[d])]
    if len(judged) < 2 or judged != list(range(len(judged))):
        raise GateRefusal(
            f"{len(captures)} capture(s) of {orientations.count} orientation(s) "
            f"({orientations.names()}): too few to judge a bias change by held-out error "
            f"(alternate temperature blocks); record a longer warm-up (more captures of "
            f"{CAPTURE_BLOCK_S:g} s over a wider temperature change){_span_said(captures, T)}")
    top = judged[-1]
    heldout, totals = heldout[: top + 1], totals[: top + 1]
    degree = _choose_degree([e for e, _ in errors[: top + 1]], errors[0][1],
                            _block_index(T))
    chosen = heldout[degree]
    without_rate = totals[degree]
    # (d, m) candidates with a rate gain of degree m, simplest first
    candidates = sorted(((d, m) for d in range(top + 1) for m in range(max(d, 1))),
                        key=lambda dm: (dm[0] + dm[1], dm[0]))
    with_rate: list[float] = []
    check = _rate_check(captures.t_s, T, x, labels, top, rebuild_noise, own_noise)
    rate = np.zeros(T.size)
    if check.tried:
        rate = temperature_rate_c_per_min(captures.t_s, T, float(check.window_s))  # type: ignore[arg-type]
        candidates = [(d, m) for d, m in candidates
                      if m <= _gain_degree_identified(rate, x, labels, d)]
        with_rate = [float(np.sqrt(np.mean(
            _heldout_rms_g(x, labels, raw, folds, d, _rate_columns(rate, x, m)) ** 2)))
            for d, m in candidates]
    best = _choose(with_rate) if with_rate else None
    use_rate = False
    if degree == 0 and best is not None:  # no change established by a degree: test the term
        d_best, m_best = candidates[best]
        use_rate = _rate_beats(errors[degree], _heldout_errors_g(
            x, labels, raw, folds, d_best, _rate_columns(rate, x, m_best)), _block_index(T))
    if degree > 0 or use_rate:
        # a change with temperature is established beyond its standard error: which model
        # describes it is a choice among models of it, by held-out error alone
        degree, best = _choose_model(totals, with_rate, candidates)
        use_rate = best is not None
        chosen, without_rate = heldout[degree], totals[degree]
    joint_errors = errors[degree]  # the held-out errors of the model kept for all axes
    rate_cols = None
    if use_rate:
        degree, gain_degree = candidates[int(best)]  # type: ignore[arg-type]
        without_rate = totals[degree]
        rate_cols = _rate_columns(rate, x, gain_degree)
        joint_errors = _heldout_errors_g(x, labels, raw, folds, degree, rate_cols)
        chosen = _rms(joint_errors[0])
    scatter = scatter_check(captures.t_s, raw, _design(x, labels, int(labels.max()) + 1,
                                                        degree, rate_cols),
                            x, labels, degree, captures.sigma_g)
    axes = _axis_choices(errors, joint_errors, degree, rate_cols is not None, _block_index(T))
    if axes.reduced:
        chosen = axes.heldout_rms_g
    coef, se, k_rate, k_se, cov = _fit_axes(x, labels, raw, degree, rate_cols, axes.choice)
    choice_cov = cov + _selection_cov(x, labels, raw, folds, coef, axes.choice, errors,
                                      joint_errors, rate_cols, _block_index(T))
    coeffs = np.tile(sfem.identity_vector()[:, None], (1, degree + 1))
    coeffs[:, 1:] = 0.0
    coeffs[sfem.BIAS, 0] = 0.0
    coeffs[sfem.BIAS, 1:] = coef
    coeff_se = np.full_like(coeffs, np.nan)
    # the stated error carries the choice of degree (the model file and the report)
    coeff_se[sfem.BIAS, 1:] = np.sqrt(np.clip(np.diagonal(choice_cov, axis1=1, axis2=2),
                                              0.0, None))
    coeff_cov = np.full((sfem.N_PARAMS, degree + 1, degree + 1), np.nan)
    coeff_cov[sfem.BIAS] = 0.0  # the constant (x⁰) is referred to centre_c: no error
    coeff_cov_choice = coeff_cov.copy()
    coeff_cov[sfem.BIAS, 1:, 1:] = cov
    coeff_cov_choice[sfem.BIAS, 1:, 1:] = choice_cov
    identifiable = np.zeros(sfem.N_PARAMS, bool)
    identifiable[sfem.BIAS] = [d > 0 for d, _ in axes.choice]
    fitted = {n: BIAS_NOTE for n, (d, _) in zip(sfem.PARAM_NAMES[:3], axes.choice,
                                                strict=True) if d > 0}
    held = {n: HELD_WHY["scale"] for n in sfem.PARAM_NAMES[3:6]}
    held.update({n: HELD_WHY["angle"] for n in sfem.PARAM_NAMES[6:]})
    if degree == 0:
        held.update({n: "held at 0: no change with temperature above the noise (degree 0 "
                        "chosen by held-out error)" for n in sfem.PARAM_NAMES[:3]})
    else:
        held.update({n: f"held at 0: no change with temperature above the noise on this "
                        f"axis ({why})" for n, why in axes.flat.items()})
    absolute = None
    common_c = _common_span_c(T, orientations)
    if orientations.count >= 2 and common_c < 2 * DISTINCT_C:
        notes_absolute = [
            f"nothing fitted absolutely: the {orientations.count} orientations were seen "
            f"together over {max(common_c, 0.0):.2f} °C only (each over its own part of "
            f"the warm-up), where a change of scale with temperature cannot be told from "
            f"a curvature of the bias; keep the orientations alternating over the whole "
            f"temperature range to fit them absolutely"]
    else:
        notes_absolute = []
    if orientations.count >= 2 and not notes_absolute:
        absolute = absolute_part(captures, orientations, x, coeffs, top, folds,
                                 None if rate_cols is None else rate_cols @ k_rate.T, g_local)
    if absolute is not None and absolute.names:
        if absolute.degree > degree:  # the absolute part's degree, chosen on its own
            pad = absolute.degree - degree
            coeffs = np.hstack([coeffs, np.zeros((sfem.N_PARAMS, pad))])
            coeff_se = np.hstack([coeff_se, np.full((sfem.N_PARAMS, pad), np.nan)])
            coeff_cov, coeff_cov_choice = (
                np.pad(c, ((0, 0), (0, pad), (0, pad)), constant_values=np.nan)
                for c in (coeff_cov, coeff_cov_choice))
        rows = [sfem.PARAM_NAMES.index(n) for n in absolute.names]
        coeffs[rows] = 0.0
        coeffs[rows, : absolute.degree + 1] = absolute.coeffs
        coeff_se[rows] = np.nan
        coeff_se[rows, : absolute.degree + 1] = absolute.stderr
        coeff_cov[rows] = np.nan  # the absolute fit gives standard errors only
        coeff_cov_choice[rows] = np.nan
        identifiable[rows] = True
        for n in absolute.names:
            fitted[n] = fitted_note(absolute, orientations)
            held.pop(n, None)
    if scatter.beyond.any() and degree == 0 and rate_cols is None:
        if absolute is not None and absolute.capture_residual_g.size:
            # a face that did not hold still is refused by name first (fitting.fit
            # checks the same after this returns)
            check_warmup_residuals(absolute.capture_residual_g, orientations,
                                   absolute.names + tuple(absolute.loose))
        raise GateRefusal(
            f"the {len(captures)} capture means wander beyond their noise: "
            f"{scatter.shown()}; no function of temperature reduces it on held-out "
            f"temperatures (degree 0 chosen by held-out error over {_block_count(T)} "
            f"temperature blocks), so the bias change with temperature cannot be "
            f"determined from this log (a board that tilts or settles, a bias drifting "
            f"with time, or one following dT/dt that no rate term here fits); clamp the "
            f"board, let it settle before recording, and record a wider temperature "
            f"change or a longer warm-up")
    if absolute is not None:  # why each scale and angle is held, with these orientations
        for n in held:
            if n in sfem.PARAM_NAMES[3:]:
                held[n] = held_note(n, absolute, orientations)
    conditioning = (f"{captures.temperature_source}: each capture's mean temperature "
                    "(a warm-up: the model in each reading's own temperature)")
    notes = [f"warm-up: {orientations.count} distinct orientation(s) "
             f"({orientations.names()}); degree {degree} chosen "
             f"by held-out error over {_block_count(T)} equal temperature blocks (interior "
             f"blocks alternately held out, the two ends always fitted: an interpolation); "
             f"valid range = the data's span",
             *([joined_note] if joined_note else []), *axes.notes, *notes_absolute]
    temperature_rate = None
    rate_axes = [n for n, (_, r) in zip(sfem.PARAM_NAMES[:3], axes.choice, strict=True) if r]
    if use_rate and not rate_axes:
        notes.append(f"rate term k·dT/dt tried ({check.why}) and not kept: it lowers the "
                     "held-out error of the three axes together, but of no axis beyond "
                     "that gain's standard error")
    elif use_rate:
        temperature_rate = {
            "gain_ug_per_c_per_min": [[float(v) * 1e6 for v in axis] for axis in k_rate],
            "stderr_ug_per_c_per_min": [[float(v) * 1e6 for v in axis] for axis in k_se],
            "basis": "k(T) = sum_j gain[axis][j] * x**j, x = (T - centre_c) / scale_c",
            "window_s": check.window_s,
            "description": RATE_DESCRIPTION.format(window=check.window_s),
            # the log's own dT/dt: what the term's effect was (export_firmware says it)
            "rate_c_per_min_range": [round(float(np.min(rate)), 4),
                                     round(float(np.max(rate)), 4)],
        }
        notes.append(
            f"rate term k·dT/dt fitted on {', '.join(rate_axes)} ({check.why}; held-out RMS "
            f"{with_rate[int(best)] * 1e3:.4f} mg with it, {without_rate * 1e3:.4f} "
            f"mg without at degree {degree}, the lowest held-out error of the models of the "
            f"change; gain of degree {gain_degree} in T): a rate-sensitive part or a "
            "temperature channel lagging the die")
    elif with_rate:
        notes.append(f"rate term k·dT/dt tried ({check.why}) and not kept: held-out error "
                     f"does not prefer it by more than {MIN_GAIN:.1%} (or, with no change "
                     "established at degree 0, beyond its standard error)")
    else:
        notes.append(f"no rate term tried: {check.why}")
    if absolute is not None:
        notes.append(absolute_summary(absolute, orientations, g_local))
    no_rate_why = None if temperature_rate is not None else (
        "tried and not kept by held-out error" if with_rate else check.why)
    scatter_note = scatter.note(degree, no_rate_why)
    if scatter_note:
        notes.append(scatter_note)
    model = ThermalModel(
        coeffs=coeffs, t_centre_c=centre, t_scale_c=scale, valid_c=(lo, hi), mode="warmup",
        identifiable=identifiable, coeff_stderr=coeff_se, method="warmup",
        temperature_rate=temperature_rate, coeff_cov=coeff_cov,
        coeff_cov_choice=coeff_cov_choice,
        temperature_source=captures.temperature_source, temperature_conditioning=conditioning,
        notes=list(notes), fitted=fitted, held=held,
        provenance={
            "input_file": os.path.basename(str(captures.path)),
            "captures": len(captures),
            "orientations": orientations.count,
            "mode": "warmup",
            "method": "warmup",
            "created_utc": _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat(),
        },
    )
    if absolute is not None and absolute.names:
        model.g_local = g_local
        model.provenance["absolute"] = {
            "mode": absolute.mode, "parameters": list(absolute.names),
            "degree": absolute.degree, "g_local": g_local,
            "residual_rms_ug": round(absolute.residual_rms_g * 1e6, 3)}
    tried = [{"degree": d, "gain_degree": m, "heldout_rms_mg": round(t * 1e3, 4)}
             for (d, m), t in zip(candidates, with_rate, strict=False)]
    report = _report(model, captures, orientations, heldout, totals, degree, chosen, tried)
    report["axis_choice"] = axes.to_dict()
    report["rate_identifiability"] = check.to_dict()
    if absolute is not None:
        report["absolute"] = absolute_report(model, absolute)
    report["capture_scatter"] = scatter.to_dict()
    report["unexplained_mg"] = scatter.unexplained_mg()
    report["unexplained_note"] = scatter_note if scatter.beyond.any() else None
    report["rmse_meaning"] = norm_rmse_meaning(
        () if absolute is None else absolute.names)
    return WarmupFit(model, report, orientations, notes, absolute, joined_note)


def norm_rmse_meaning(absolute_names: tuple[str, ...]) -> str:
    """What a warm-up report's ``rmse_before_mg``/``rmse_after_mg`` (added by
    :func:`calibration.fitting.fit`) measure: Eq. 9's |g| error, which a warm-up's fit
    does not minimise, and which holds whatever it leaves unidentified."""
    unknown = [n for n in ("bx", "by", "bz", "sx", "sy", "sz") if n not in absolute_names]
    what = ("rmse_before_mg / rmse_after_mg: RMS over the capture means of |reading| - "
            "g_local (Eq. 9), mg, before and after the model.")
    if not unknown:
        return what
    return (f"{what} Not a figure of the fit: the warm-up does not identify the constant "
            f"part of {', '.join(unknown)}, so both contain the sensor's constant offset "
            "and scale error along gravity, and 'after' also moves with centre_c (the bias "
            "change is referred to it: a capture at centre_c is not changed). The fit's "
            "figure is heldout_rms_mg_xyz")


def absolute_summary(absolute: AbsoluteFit, orientations: Orientations,
                     g_local: float) -> str:
    """The note on what the orientations determine absolutely (or that they do not)."""
    units = dict(zip(sfem.PARAM_NAMES, sfem.PARAM_UNITS, strict=True))
    loose = "".join(f"; {n} determined only to ±{v:.2g} {units[n]} and held"
                    for n, v in absolute.loose.items())
    if not absolute.names:
        return (f"the {orientations.count} orientations ({orientations.names()}) determine no "
                f"SFEM parameter absolutely in {absolute.mode} mode (identifiability of their "
                f"directions){loose}: only each axis' bias change is fitted")
    gravity = f", |g| = {g_local:.6f} g" if absolute.mode == "norm" else ""
    return (f"absolute: {', '.join(absolute.names)} determined by the "
            f"{orientations.count} orientations in {absolute.mode} mode{gravity}; residual "
            f"RMS {absolute.residual_rms_g * 1e6:.1f} ug after the fit{loose}")


def absolute_report(model: ThermalModel, absolute: AbsoluteFit) -> dict[str, Any]:
    """``report["absolute"]``: each absolutely fitted parameter at centre_c ± its standard
    error, its slope per °C, and what the orientations left undetermined."""
    phys = model.physical_coeffs()
    se = model.coeff_stderr / model.t_scale_c ** np.arange(model.degree + 1)[None, :]  # type: ignore[operator]
    params = {}
    for n in absolute.names:
        k = sfem.PARAM_NAMES.index(n)
        params[n] = {"unit": sfem.PARAM_UNITS[k], "value": float(phys[k, 0]),
                     "stderr": float(se[k, 0]),
                     "per_c": [float(v) for v in phys[k, 1: absolute.degree + 1]],
                     "per_c_stderr": [float(v) for v in se[k, 1: absolute.degree + 1]]}
    return {"mode": absolute.mode, "degree": absolute.degree,
            "parameters": params,
            "residual_rms_ug": (round(absolute.residual_rms_g * 1e6, 3)
                                if absolute.names else None),
            "not_determined": [n for n in sfem.PARAM_NAMES if n not in absolute.names],
            "too_loose": {n: {"stderr": v, "unit": sfem.PARAM_UNITS[sfem.PARAM_NAMES.index(n)]}
                          for n, v in absolute.loose.items()}}


RATE_DESCRIPTION = (
    "bias += k * dT/dt (k in ug per degC/min per axis); dT/dt in degC/min is the time "
    "derivative of a robust local parabola of the capture-mean temperatures over "
    "+/-{window:g}/2 s (centred: not available to a causal consumer before that much later)")


@dataclass
class RateCheck:
    """Whether a warm-up's captures identify a rate term (:func:`_rate_check`)."""
    tried: bool
    why: str
    window_s: float | None = None  # dT/dt read over it
    share: float = 0.0  # of the rate's sum of squares left after the polynomial in T
    noise_c_per_min: float = float("nan")  # dT/dt's noise over window_s
    residual_c_per_min: float = 0.0  # RMS of the rate left after the polynomial in T
    noise_source: str = ""  # which estimate of the temperature's noise, and why

    def to_dict(self) -> dict[str, Any]:
        return {"tried": self.tried, "why": self.why, "window_s": self.window_s,
                "share_not_a_function_of_t": round(self.share, 4),
                "noise_c_per_min": (round(self.noise_c_per_min, 4)
                                    if np.isfinite(self.noise_c_per_min) else None),
                "residual_rms_c_per_min": round(self.residual_c_per_min, 4),
                "temperature_noise": self.noise_source}


def _rate_check(t_s: np.ndarray, T: np.ndarray, x: np.ndarray, labels: np.ndarray,
                top: int, rebuild_noise: Callable[[float], float] | None = None,
                own_noise: CaptureTemperatureNoise | None = None) -> RateCheck:
    """Whether dT/dt is identifiable beside the polynomial in T, and its window.

    A rate gain k and the bias polynomial are separable only where dT/dt is not itself a
    function of T over the captures: a monotone warm-up at a steady or an exponential
    rate has dT/dt ≈ f(T) and any polynomial absorbs k·dT/dt; a rest and then a heating
    (zero and large rates at the same temperature), or a heating and a cooling, do not.
    Measured as the share of the rate column's sum of squares left after projecting out
    the orientations' constants and x¹ … x^top (:data:`RATE_MIN_SHARE`). The window is
    the shortest whose dT/dt noise, for this channel's noise (quantisation included), is
    at most :data:`RATE_NOISE_SHARE` of that residual's RMS
    (:func:`calibration.temperature_conditioning.rate_window_s`); on a temperature rebuilt
    from a coarse channel that noise includes the rebuild's own error in dT/dt
    (``rebuild_noise``, :mod:`calibration.rebuild_rate_noise`): slow, largest where the die
    turns inside a step, and invisible in the rebuilt trace's second differences.

    The channel's noise is each capture mean's own where its raw samples show it
    (``own_noise``: :func:`calibration.temperature_conditioning.capture_temperature_noise`,
    their sub-means' scatter inside the capture, where it averages down as white noise),
    else the capture means' second differences (:func:`calibration.temperature_conditioning.
    temperature_noise_c`), which on sparse captures of a turning warm-up read its
    curvature as noise; the check's text and ``noise_source`` say which."""
    k = int(labels.max()) + 1
    P = _design(x, labels, k, max(top, 1))

    def residual(rate: np.ndarray) -> np.ndarray:
        return rate - P @ np.linalg.lstsq(P, rate, rcond=None)[0]

    source = ("from the capture means' second differences" if own_noise is None
              else own_noise.said())
    found = rate_window_s(t_s, T, lambda r: float(np.sqrt(np.mean(residual(r) ** 2))),
                          RATE_NOISE_SHARE, rebuild_noise,
                          None if own_noise is None else own_noise.per_capture_c)
    if found is None:
        return RateCheck(False, "dT/dt not resolved: over every window its noise exceeds "
                                f"{RATE_NOISE_SHARE:.0%} of the part of it that is not a "
                                "function of T (a steady warm-up, or a channel's jitter; "
                                f"temperature noise {source})", noise_source=source)
    window, noise = found
    rate = temperature_rate_c_per_min(t_s, T, window)
    res = residual(rate)
    share = float(np.sum(res ** 2) / max(float(np.sum(rate ** 2)), 1e-30))
    rms = float(np.sqrt(np.mean(res ** 2)))
    shown = (f"{share:.1%} of dT/dt (read over {window:g} s, noise {noise:.2g} °C/min, "
             f"temperature noise {source}) is not a function of T, RMS {rms:.2g} °C/min")
    if share < RATE_MIN_SHARE:
        return RateCheck(False, f"dT/dt is nearly a function of T over these captures "
                                f"({shown}; {RATE_MIN_SHARE:.1%} needed): the polynomial in "
                                "T absorbs a rate term", window, share, noise, rms, source)
    return RateCheck(True, shown, window, share, noise, rms, source)


def _gain_degree_identified(rate: np.ndarray, x: np.ndarray, labels: np.ndarray,
                            degree: int) -> int:
    """The highest rate-gain degree m whose columns dT/dt·x^j (j ≤ m) each keep at least
    :data:`RATE_MIN_SHARE` (j = 0) or :data:`GAIN_MIN_SHARE` (j ≥ 1: no resolution test
    guards these) of their sum of squares after projecting out the degree-d
    design and the lower rate columns (:func:`_rate_check`'s test, column by column). In
    a heating, dT/dt·x^j is as much a function of T as dT/dt is, so a gain that changes
    with T is identified only where the heating and the rest (or the cooling) overlap in
    temperature; 0 when even the constant gain is not (then no candidate with it)."""
    k = int(labels.max()) + 1
    X = _design(x, labels, k, degree)
    top = -1
    for j in range(max(degree, 1)):
        col = rate * x ** j
        res = col - X @ np.linalg.lstsq(X, col, rcond=None)[0]
        least = RATE_MIN_SHARE if j == 0 else GAIN_MIN_SHARE
        if float(np.sum(res ** 2)) < least * max(float(np.sum(col ** 2)), 1e-30):
            break
        top, X = j, np.column_stack([X, col])
    return top


def _rate_beats(without: tuple[np.ndarray, np.ndarray], with_rate: tuple[np.ndarray, np.ndarray],
                block: np.ndarray) -> bool:
    """The rate term's own held-out test, as a degree's (:func:`_beats`): on the same
    held-out captures, its squared errors summed over the axes lower by more than
    :data:`MIN_GAIN` and by more than the gain's standard error."""
    (e0, i0), (e1, i1) = without, with_rate
    if i0.size == 0 or i0.shape != i1.shape or not np.array_equal(i0, i1):
        return False
    return _beats(e0, e1, block[i0])


def rate_offset_g(model: ThermalModel, t_s: np.ndarray, temperature_c: np.ndarray
                  ) -> np.ndarray:
    """(N,3) a warm-up model's rate term k(T)·dT/dt at each row, g (zeros without one).

    ``temperature_c`` must be the capture-mean temperature the model was fitted in."""
    t = np.asarray(t_s, float)
    term = model.temperature_rate
    if not term:
        return np.zeros((t.size, 3))
    gain_g = np.asarray(term["gain_ug_per_c_per_min"], float) * 1e-6  # (3, m+1)
    rate = temperature_rate_c_per_min(t, temperature_c, float(term["window_s"]))
    cols = _rate_columns(rate, model.x_of(temperature_c), gain_g.shape[1] - 1)
    return cols @ gain_g.T


def _rate_columns(rate: np.ndarray, x: np.ndarray, gain_degree: int) -> np.ndarray:
    """(N, m+1) dT/dt · x^j, j = 0 … m: the rate term's columns (gain a polynomial in x)."""
    return np.asarray(rate, float)[:, None] * np.vander(x, gain_degree + 1, increasing=True)


def _choose_degree(errors_g: list[np.ndarray], held: np.ndarray, block: np.ndarray) -> int:
    """One degree for the three axes: the lowest that no higher one beats (:func:`_beats`)
    in held-out squared error summed over the axes. ``errors_g[d]``: (n, 3) errors of
    the held-out captures ``held`` (indices) at degree d; ``block``: each capture's
    temperature block. One degree, not one per axis: the axes share a die and its
    temperature history, and a curvature too weak to show above one axis' capture noise
    (the twin's x: held-out 0.0183 mg at degree 1 and 2) shows in the sum."""
    degree = 0
    for d in range(1, len(errors_g)):
        if _beats(errors_g[degree], errors_g[d], block[held]):
            degree = d
    return degree


def _beats(err_low: np.ndarray, err_high: np.ndarray, block: np.ndarray) -> bool:
    """True when the higher degree's held-out errors ``err_high`` beat the lower degree's
    ``err_low`` (signed, g: (n,) for one axis or (n, 3) summed over the axes) by more than
    :data:`MIN_GAIN` in RMS *and* by more than the standard error of that gain; or, by
    less than MIN_GAIN, where the held-out temperature blocks' mean errors are lower beyond
    chance (:data:`STRONG_GAIN_P`, :func:`_block_means_beat`). The gain is a mean over
    held-out captures whose errors within one temperature block are correlated (neighbours
    in time share a slow drift), so its standard error is counted over blocks: s_b =
    Σ_{i∈b} gain_i, G = Σ s_b / n, se² = B/(B − 1) · Σ_b (s_b − n_b·G)² / n². A higher
    degree that fits the noise of the fitted captures gains nothing on average, and its
    chance gains stay within that."""
    lo = err_low.reshape(err_low.shape[0], -1)
    hi = err_high.reshape(err_high.shape[0], -1)
    if lo.shape != hi.shape or lo.size == 0:
        return False
    sq_low, sq_high = np.sum(lo ** 2, axis=1), np.sum(hi ** 2, axis=1)
    sizable = np.sqrt(np.mean(sq_high)) < np.sqrt(np.mean(sq_low)) * (1.0 - MIN_GAIN)
    gain = sq_low - sq_high
    blocks, inverse = np.unique(block, return_inverse=True)
    if blocks.size < 2:
        return bool(sizable)
    if not sizable:
        return _block_means_beat(lo, hi, inverse, blocks.size)
    sums = np.bincount(inverse, weights=gain)
    counts = np.bincount(inverse)
    mean = float(np.sum(sums) / gain.size)
    se = float(np.sqrt(blocks.size / (blocks.size - 1)
                       * np.sum((sums - counts * mean) ** 2)) / gain.size)
    return mean > se


def _block_means_beat(lo: np.ndarray, hi: np.ndarray, inverse: np.ndarray,
                      n_blocks: int) -> bool:
    """Whether the held-out blocks' mean errors (each axis) are lower with ``hi`` than with
    ``lo`` beyond chance: per block b, g_b = Σ_axes (mean_b lo)² − (mean_b hi)²; a
    one-sided Wilcoxon signed-rank test of g_b > 0 over the B blocks at
    :data:`STRONG_GAIN_P` (never reached with 7 blocks or fewer). A capture's white noise
    averages out of a block's mean; a bias change the higher degree models does not."""
    counts = np.bincount(inverse, minlength=n_blocks).astype(float)

    def block_means(err: np.ndarray) -> np.ndarray:  # (B, axes)
        return np.column_stack([np.bincount(inverse, weights=c, minlength=n_blocks)
                                for c in err.T]) / counts[:, None]

    g = np.sum(block_means(lo) ** 2 - block_means(hi) ** 2, axis=1)
    if not np.any(g):
        return False
    p = float(sp_stats.wilcoxon(g, alternative="greater").pvalue)
    return p <= STRONG_GAIN_P


def _choose_model(totals: list[float], with_rate: list[float],
                  candidates: list[tuple[int, int]]) -> tuple[int, int | None]:
    """The model of an established change with temperature: (degree, index into
    ``candidates`` of its rate gain, None without a rate term).

    Called once a change is established beyond its standard error (:func:`_choose_degree`
    above degree 0, or a rate term by :func:`_rate_beats`). That test guards the answer
    "no change above the noise" (degree 0, refused when the captures wander); between
    models that all describe the change it asks too much: the held-out gain of a weak
    curvature is within its standard error on a long log whose capture noise dominates
    the held-out captures (gen2 warm-up w1059: on the benchmark's held-out 5-s means x
    reads 0.0218 mg at degree 2, 0.0243 at degree 1, the firmwares' cubic 0.0219; here
    degree 2 gains 0.4 % of held-out RMS at a standard error of 1.3 times the gain),
    and a rate term read over a short window is kept against the chosen degree
    where one more degree does as well (w1001: degree 3 without it 0.0797 mg, degree 2
    with it 0.0798 mg). Here every model of degree ≥ 1, with or without a rate gain
    (``totals[d]``; ``with_rate[i]`` for ``candidates[i] = (d, m)``), is ordered by its
    number of temperature coefficients (d, or d + m + 1), a model without a rate term
    first at equal count, and the first whose held-out RMS is within :data:`MIN_GAIN` of
    the lowest is taken: more coefficients must buy more than that. (Not a walk that
    moves on whenever a model beats the current one by it: among many models at about one
    level, the first to cross below the simplest would be taken, not the simplest near the
    lowest.)
    """
    models: list[tuple[tuple[int, int, int], float, int, int | None]] = [
        ((d, 0, d), totals[d], d, None) for d in range(1, len(totals))]
    models += [((d + m + 1, 1, d), t, d, i)
               for i, ((d, m), t) in enumerate(zip(candidates, with_rate, strict=False))
               if np.isfinite(t)]
    models.sort(key=lambda mdl: mdl[0])
    lowest = min(mdl[1] for mdl in models)
    _, _, degree, index = next(mdl for mdl in models if mdl[1] * (1.0 - MIN_GAIN) <= lowest)
    return degree, index


def _choose(totals: list[float]) -> int:
    """The lowest degree no higher one beats by more than :data:`MIN_GAIN`."""
    degree = 0
    for d in range(1, len(totals)):
        if totals[d] < totals[degree] * (1.0 - MIN_GAIN):
            degree = d
    return degree


def _common_span_c(T: np.ndarray, orientations: Orientations) -> float:
    """°C over which every orientation was seen (negative when two never overlap): where
    the absolute part can tell a scale's change with temperature from the bias's."""
    k = orientations.count
    lows = [float(np.min(T[orientations.labels == o])) for o in range(k)]
    highs = [float(np.max(T[orientations.labels == o])) for o in range(k)]
    return min(highs) - max(lows)


def _joined_by_drift(t_s: np.ndarray, T: np.ndarray, raw_g: np.ndarray,
                     orientations: Orientations) -> tuple[Orientations, str | None]:
    """One placement whose direction drifts with temperature, split by the clustering,
    joined back; and a note saying so (None when nothing was joined).

    The gate clusters directions by leader clustering within a fixed angle (2° or the
    noise's): a board resting at one orientation while its bias changes by tens of mg
    (a consumer part at 1-2 mg/°C over a 30 °C warm-up: 30-60 mg, 2-3.5°) drifts out of
    its first cluster and is counted as several orientations, each with its own unknown
    gravity constant, which takes the bias change between them away from the fit (or
    refuses the log as orientations at separate temperatures). A re-placement of the
    board is a jump between the captures before and after it; a bias drift is not.
    Clusters are joined where two captures consecutive in time fall in different
    clusters with directions within the clustering angle of each other (no jump), and
    only when the clusters' directions differ by no more than the clustering angle plus
    what a bias tempco of :data:`~calibration.gate.BIAS_TEMPCO_MAX_G_PER_C` on two axes
    could turn the reading through over the two clusters' temperature span (a slow
    tilt beyond that is not a bias change, and stays split).
    """
    k = orientations.count
    if k < 2:
        return orientations, None
    labels = orientations.labels
    norm = np.linalg.norm(raw_g, axis=1)
    u = raw_g / np.where(norm > 0, norm, 1.0)[:, None]
    order = np.argsort(t_s, kind="stable")
    la, uo = labels[order], u[order]
    thr = np.radians(orientations.threshold_deg)
    g = float(np.median(norm))
    parent = list(range(k))

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    step = np.arccos(np.clip(np.sum(uo[1:] * uo[:-1], axis=1), -1.0, 1.0))
    for i in np.flatnonzero((la[1:] != la[:-1]) & (step <= thr)):
        a, b = root(int(la[i])), root(int(la[i + 1]))
        if a == b:
            continue
        members = np.flatnonzero(np.isin([root(j) for j in range(k)], [a, b]))
        span_c = float(np.ptp(T[np.isin(labels, members)]))
        allowed = thr + np.sqrt(2.0) * BIAS_TEMPCO_MAX_G_PER_C * span_c / max(g, 1e-9)
        dirs = orientations.directions[members]
        if np.arccos(np.clip(np.min(dirs @ dirs.T), -1.0, 1.0)) <= allowed:
            parent[b] = a
    roots = np.array([root(j) for j in range(k)])
    if np.unique(roots).size == k:
        return orientations, None
    new_id = {r: i for i, r in enumerate(np.unique(roots))}
    joined = np.array([new_id[r] for r in roots])[labels]
    m = len(new_id)
    sums = np.zeros((m, 3))
    np.add.at(sums, joined, u)
    dirs = sums / np.linalg.norm(sums, axis=1, keepdims=True)
    merged = Orientations(joined, dirs, np.bincount(joined, minlength=m),
                          orientations.threshold_deg)
    note = (f"{k} direction clusters ({orientations.names()}) joined into {m} "
            f"orientation(s) ({merged.names()}): the direction drifts continuously with "
            f"the temperature, with no jump between consecutive captures (a bias change "
            f"of the resting board, not a re-placement)")
    return merged, note


def _check_connected(T: np.ndarray, orientations: Orientations) -> None:
    """Refuse orientations seen at separate temperatures (GateRefusal).

    Each orientation has its own unknown gravity constant, so a bias change is seen
    only within an orientation's own temperatures; between two orientations recorded
    at different temperatures (a cold log lying on one face, a hot one on another) the
    change of bias cannot be told from the change of orientation. The orientations'
    temperature intervals must overlap into one.
    """
    k = orientations.count
    if k < 2:
        return
    spans = sorted((float(np.min(T[orientations.labels == o])),
                    float(np.max(T[orientations.labels == o])), o) for o in range(k))
    reach = spans[0][1]
    for lo, hi, _ in spans[1:]:
        if lo > reach + DISTINCT_C:
            shown = "; ".join(
                f"{orientations.name(o)} {a:.2f} .. {b:.2f} °C"
                for a, b, o in spans[:4])
            raise GateRefusal(
                f"{k} orientations recorded at separate temperatures ({shown}): a change of "
                f"bias between them cannot be told from the change of orientation; record "
                f"one orientation across the whole temperature range")
        reach = max(reach, hi)


def _design(x: np.ndarray, labels: np.ndarray, k: int, degree: int,
            rate_cols: np.ndarray | None = None) -> np.ndarray:
    """Columns: one constant per orientation (gravity's projection), x¹ … x^d, then the
    rate term's (:func:`_rate_columns`) when given."""
    onehot = (labels[:, None] == np.arange(k)[None, :]).astype(float)
    powers = np.vander(x, degree + 1, increasing=True)[:, 1:]
    return np.hstack([onehot, powers] + ([rate_cols] if rate_cols is not None else []))


@dataclass(frozen=True)
class AxisChoices:
    """Each axis' model, from the joint choice down (:func:`_axis_choices`)."""

    choice: tuple[tuple[int, bool], ...]  # per axis: (degree, rate term kept)
    heldout_rms_g: np.ndarray  # (3,) each axis' held-out RMS with its own choice
    joint_rms_g: np.ndarray  # (3,) with the joint choice
    joint: tuple[int, bool]
    notes: tuple[str, ...] = ()
    flat: dict[str, str] = field(default_factory=dict)  # bias held at 0 → why

    @property
    def reduced(self) -> bool:
        return any(c != self.joint for c in self.choice)

    def to_dict(self) -> dict[str, Any]:
        return {n: {"degree": d, "rate_term": r,
                    "heldout_rms_mg": round(float(h) * 1e3, 4),
                    "heldout_rms_mg_joint": round(float(j) * 1e3, 4)}
                for n, (d, r), h, j in zip(sfem.PARAM_NAMES[:3], self.choice,
                                           self.heldout_rms_g, self.joint_rms_g, strict=True)}


def _axis_choices(errors: list[tuple[np.ndarray, np.ndarray]],
                  joint_errors: tuple[np.ndarray, np.ndarray], degree: int,
                  with_rate: bool, block: np.ndarray) -> AxisChoices:
    """Each axis keeps the joint choice only where it establishes a change on that axis'
    own held-out error; otherwise no change, or the simplest model below the joint one
    whose held-out error on that axis is no higher.

    The degree (and the rate term) are chosen on the three axes together
    (:func:`_choose_degree`, :func:`_choose_model`): a curvature too weak for one axis'
    noise shows in the sum, and a model chosen per axis takes that axis' selection noise
    (each axis its own degree, rate term and gain degree, by the same steps on its own
    held-out error, was measured and not kept: on issue 20's inclinometer it gave y a
    rate gain of degree 1, held-out 0.4650 → 0.6271 mg on the benchmark's held-out 5-s
    means, and the twin's x a line, 0.0076 → 0.0080 mg; docs/benchmarks.md, "Each axis
    its own model"). Whether an axis changes at all is its own question: the joint model
    must lower that axis' held-out squared error by more than :data:`MIN_GAIN` and by
    more than that gain's standard error over the temperature blocks (:func:`_beats`, the
    test a degree above 0 passes on the three axes); a gain within its own standard error
    is no evidence, and the axis is held (no change with temperature above its noise).
    Whether an axis' bias follows dT/dt is its own question too, by the same test: a joint
    rate term is kept on an axis only where it lowers that axis' held-out error at the
    joint degree beyond the gain's standard error (the rate gain is one coefficient per
    axis, and a rate-sensitive part or a lagging channel need not show on every axis; on
    issue 20's inclinometer x's gain was −55 ± 26 µg/(°C/min) and its held-out gain
    within its standard error: kept, x read 0.2773 mg on the benchmark's held-out 5-s
    means, without it 0.2462, against 0.2619 uncompensated). A
    z-only cubic with a rate term gave a flat x or y a model of a change (9 with z's rate
    term) on 15 of 80 axes by the earlier rule (no higher held-out error), on 0 by this
    one. An axis whose change is established but whose own held-out error is no lower
    with the joint model than with a simpler one (a lower degree without the rate term)
    takes the simpler: the report would otherwise print "compensated" above
    "uncompensated" for it. The candidates are judged on the same held-out captures (else
    the axis keeps the joint).

    ``errors[d]``: the held-out (errors, captures) at degree d without the rate term, as
    :func:`fit_warmup` computed them to choose the degree; ``joint_errors``: those of the
    joint model (``errors[degree]``, or with the rate term ``with_rate``); ``block``: each
    capture's temperature block (:func:`_block_index`).
    """
    joint = (degree, with_rate)
    joint_e, joint_idx = joint_errors
    joint_rms = _rms(joint_e)
    simpler = [(d, False) for d in range(degree + with_rate)]
    choice = [joint, joint, joint]
    rms = joint_rms.copy()
    unproven = (_not_beaten(errors[0], joint_errors, block) if joint != (0, False)
                else [False, False, False])
    for a in (a for a in range(3) if unproven[a]):
        choice[a], rms[a] = (0, False), float(_rms(errors[0][0])[a])
    rate_unproven = [c == joint and u for c, u in
                     zip(choice, _not_beaten(errors[degree], joint_errors, block), strict=True)
                     ] if with_rate else [False, False, False]
    for a in (a for a in range(3) if rate_unproven[a]):
        choice[a], rms[a] = (degree, False), float(_rms(errors[degree][0])[a])
    for d, _ in simpler:  # simplest first: the first no worse than the axis' model wins
        e, idx = errors[d]
        if not np.array_equal(idx, joint_idx) or idx.size == 0:
            continue
        for a, v in enumerate(_rms(e)):
            if choice[a] != (0, False) and d < choice[a][0] + choice[a][1] and v <= rms[a]:
                choice[a], rms[a] = (d, False), v
    notes, flat = [], {}
    for n, (d, r), v, j, u, ru in zip(sfem.PARAM_NAMES[:3], choice, rms, joint_rms, unproven,
                                      rate_unproven, strict=True):
        if (d, r) == joint:
            continue
        why = (f"held-out RMS {v * 1e3:.4f} mg at degree {d}, {j * 1e3:.4f} mg with the "
               f"joint degree {degree}{' and rate term' if joint[1] else ''}")
        if u:
            notes.append(f"{n}: degree 0, no rate term: the joint model does not lower its "
                         f"own held-out error beyond that gain's standard error ({why})")
        elif ru:
            notes.append(f"{n}: degree {d}, no rate term: the rate term does not lower its "
                         f"own held-out error beyond that gain's standard error ({why})")
        else:
            notes.append(f"{n}: degree {d}, no rate term: its own held-out error is no "
                         f"lower with the joint model ({why})")
        if d == 0:
            flat[n] = why
    return AxisChoices(tuple(choice), rms, joint_rms, joint, tuple(notes), flat)


def _not_beaten(simpler: tuple[np.ndarray, np.ndarray],
                joint: tuple[np.ndarray, np.ndarray], block: np.ndarray) -> list[bool]:
    """Per axis: True where the joint model's held-out errors do not beat the simpler
    model's on that axis beyond the gain's standard error (:func:`_beats`); all False where
    the two were not judged on the same held-out captures. ``simpler``, ``joint``: (errors
    (n, 3), captures) as :func:`_heldout_errors_g` gives them."""
    (e_lo, idx_lo), (e_joint, idx_joint) = simpler, joint
    if not (np.array_equal(idx_lo, idx_joint) and idx_lo.size):
        return [False, False, False]
    return [not _beats(e_lo[:, a], e_joint[:, a], block[idx_lo]) for a in range(3)]


def _fit_axes(x: np.ndarray, labels: np.ndarray, raw: np.ndarray, degree: int,
              rate_cols: np.ndarray | None, choice: tuple[tuple[int, bool], ...]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_fit` with each axis at its own (degree, rate) from ``choice``, padded to the
    joint shape: a coefficient or rate gain an axis does not fit is 0 with no error."""
    coef, se, k_rate, k_se, cov = _fit(x, labels, raw, degree, rate_cols)
    for d, r in set(choice) - {(degree, rate_cols is not None)}:
        c2, s2, k2, ks2, v2 = _fit(x, labels, raw, d, rate_cols if r else None)
        for a in (a for a, c in enumerate(choice) if c == (d, r)):
            coef[a], se[a], cov[a] = 0.0, 0.0, 0.0
            coef[a, :d], se[a, :d], cov[a, :d, :d] = c2[a], s2[a], v2[a]
            k_rate[a], k_se[a] = (k2[a], ks2[a]) if r else (0.0, 0.0)
    return coef, se, k_rate, k_se, cov


def _selection_cov(x: np.ndarray, labels: np.ndarray, raw: np.ndarray, folds: np.ndarray,
                   coef: np.ndarray, choice: tuple[tuple[int, bool], ...],
                   errors: list[tuple[np.ndarray, np.ndarray]],
                   joint_errors: tuple[np.ndarray, np.ndarray],
                   rate_cols: np.ndarray | None, block: np.ndarray) -> np.ndarray:
    """(3, d, d) each axis' model-selection term of its drift coefficients' covariance, g².

    Held-out error chooses the degree, and where the noise looks curved a higher degree
    is chosen and its slope moves with that curvature; the chosen model's own covariance
    (:func:`_fit`), as if it had been the only one tried, then understates the slope's
    spread over noise draws (1.6–1.7× at the span's edge on a straight line;
    docs/benchmarks.md, "A warm-up's stated bias slope error"). The term is that of a
    model-averaged variance (Buckland, Burnham & Augustin 1997), at full weight over the
    models the data could not tell from the chosen one: for each lower degree d' ≥ 1 that
    the axis' chosen model (``choice``: degree, rate term) does not beat on that axis'
    own held-out error beyond the gain's standard error (:func:`_beats`), the outer
    product of the two coefficient vectors' difference (d' fitted with the axis' own rate
    setting, zero-padded). Zero where degree 1 is chosen or every lower degree is beaten.

    It is the error of the slope as the data know it (the model file's standard errors,
    the report's slope); the gate judges the curve that is applied by its own fit's
    covariance (:attr:`ThermalModel.coeff_cov`): a steep local slope a lower degree
    cannot be told from is still the slope the compensation applies.
    """
    term = np.zeros((3, coef.shape[1], coef.shape[1]))
    lower_errors: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # degree d with the rate term
    lower_coef: dict[tuple[int, bool], np.ndarray] = {}  # each lower model fitted once
    for a, (d_a, r_a) in enumerate(choice):
        # the axis' own held-out errors: the joint model's, or a simpler one's without
        # the rate term (:func:`_axis_choices`)
        own = joint_errors if (d_a, r_a) == (coef.shape[1], rate_cols is not None) \
            else errors[d_a]
        for d in range(1, d_a):
            if r_a and d not in lower_errors:
                lower_errors[d] = _heldout_errors_g(x, labels, raw, folds, d, rate_cols)
            lower = lower_errors[d] if r_a else errors[d]
            if not (np.array_equal(lower[1], own[1]) and lower[1].size):
                continue
            if _beats(lower[0][:, a], own[0][:, a], block[own[1]]):
                continue
            if (d, r_a) not in lower_coef:
                lower_coef[d, r_a] = _fit(x, labels, raw, d, rate_cols if r_a else None)[0]
            diff = -coef[a].copy()
            diff[:d] += lower_coef[d, r_a][a]
            term[a] += np.outer(diff, diff)
    return term


def _fit(x: np.ndarray, labels: np.ndarray, raw: np.ndarray, degree: int,
         rate_cols: np.ndarray | None = None
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(3, d) drift coefficients and their standard errors; (3, m+1) rate gains (g per
    °C/min, polynomial in x) and theirs ((3, 0) without ``rate_cols``); (3, d, d) each
    axis' covariance of its drift coefficients, g² (the rate term's columns marginalised:
    with a rate term fitted, a lag's steep onset is the term's, not the slope's)."""
    k = int(labels.max()) + 1
    X = _design(x, labels, k, degree, rate_cols)
    beta, *_ = np.linalg.lstsq(X, raw, rcond=None)
    dof = max(X.shape[0] - X.shape[1], 1)
    s2 = np.sum((raw - X @ beta) ** 2, axis=0) / dof
    cov = np.linalg.pinv(X.T @ X)
    se = np.sqrt(np.clip(np.diag(cov), 0, None))[k:, None] * np.sqrt(s2)[None, :]
    e = k + degree
    drift_cov = cov[k:e, k:e][None, :, :] * s2[:, None, None]
    return beta[k:e].T, se[:degree].T, beta[e:].T, se[degree:].T, drift_cov


def _block_count(temperature_c: np.ndarray) -> int:
    """How many equal temperature blocks :func:`_folds` cuts the span into."""
    span_c = float(np.ptp(np.asarray(temperature_c, float)))
    return max(MIN_HOLDOUT_BLOCKS, min(HOLDOUT_BLOCKS, int(span_c // DISTINCT_C)))


def _block_index(temperature_c: np.ndarray) -> np.ndarray:
    """Each capture's temperature block (0 … :func:`_block_count` − 1, equal widths)."""
    T = np.asarray(temperature_c, float)
    lo, n_blocks = float(np.min(T)), _block_count(T)
    width = max(float(np.max(T)) - lo, 1e-9) / n_blocks
    return np.minimum(((T - lo) // width).astype(int), n_blocks - 1)


def _folds(temperature_c: np.ndarray) -> np.ndarray:
    """0/1 per capture (held out in one fold, fitted in the other), 2 = always fitted.

    The captures' temperature span is cut into equal blocks, :data:`HOLDOUT_BLOCKS` of
    them or fewer so none is narrower than :data:`DISTINCT_C` (at least
    :data:`MIN_HOLDOUT_BLOCKS`); interior blocks alternate 0/1, the lowest and highest
    blocks are 2. Every held-out capture then lies between fitted temperatures: the
    test is an interpolation, as a compensation inside the valid range (the data's
    span) is. Blocks of temperature, not time: a warm-up that rests and then heats has
    its whole temperature change in a small part of its duration.
    """
    block = _block_index(temperature_c)
    folds = block % 2
    folds[(block == 0) | (block == _block_count(temperature_c) - 1)] = 2
    return folds


def _heldout_rms_g(x: np.ndarray, labels: np.ndarray, raw: np.ndarray, folds: np.ndarray,
                   degree: int, rate_cols: np.ndarray | None = None) -> np.ndarray:
    """(3,) RMS over held-out captures per axis, g, both ways round (NaN: none judged)."""
    return _rms(_heldout_errors_g(x, labels, raw, folds, degree, rate_cols)[0])


def _rms(errors_g: np.ndarray) -> np.ndarray:
    """(3,) RMS of (n, 3) errors; NaN without any."""
    if errors_g.shape[0] == 0:
        return np.full(3, np.nan)
    return np.sqrt(np.mean(errors_g ** 2, axis=0))


def _heldout_errors_g(x: np.ndarray, labels: np.ndarray, raw: np.ndarray, folds: np.ndarray,
                      degree: int, rate_cols: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) errors of the held-out captures, g, fitted on one fold and judged on the
    other, both ways round; and those captures' indices.

    A held-out capture whose orientation the fitted half never saw cannot be predicted
    (its constant is unknown) and is not counted.
    """
    k = int(labels.max()) + 1
    errs: list[np.ndarray] = []
    where: list[np.ndarray] = []
    for held in (0, 1):
        fit, test = folds != held, folds == held
        seen = np.isin(labels, np.unique(labels[fit])) & test
        n_rate = 0 if rate_cols is None else rate_cols.shape[1]
        if not seen.any() or fit.sum() <= k + degree + n_rate:
            continue
        Xf = _design(x[fit], labels[fit], k, degree,
                     None if rate_cols is None else rate_cols[fit])
        beta, *_ = np.linalg.lstsq(Xf, raw[fit], rcond=None)
        Xs = _design(x[seen], labels[seen], k, degree,
                     None if rate_cols is None else rate_cols[seen])
        errs.append(raw[seen] - Xs @ beta)
        where.append(np.flatnonzero(seen))
    if not errs:
        return np.zeros((0, 3)), np.zeros(0, int)
    return np.vstack(errs), np.concatenate(where)


def _count_distinct(values: np.ndarray, tol: float) -> int:
    """Temperatures ``tol`` apart: the number of ``tol``-wide bins the values occupy. (Not
    the gaps wider than ``tol`` between sorted values: a dense continuous warm-up has none
    and would count as one temperature however far it went.)"""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return int(np.unique(np.floor((v - v.min()) / tol)).size) if v.size else 0


def _report(model: ThermalModel, captures: Recording, orientations: Orientations,
            heldout: list[np.ndarray], totals: list[float], degree: int,
            chosen: np.ndarray, rate_tried: list[dict[str, Any]]) -> dict[str, Any]:
    phys = model.physical_coeffs()
    lo, hi = model.valid_c  # type: ignore[misc]
    change = model.params_vector_at(hi, True)[:3] - model.params_vector_at(lo, True)[:3]
    return {
        "recording": os.path.basename(str(captures.path)),
        "mode": "warmup",
        "method": "warmup",
        "captures": len(captures),
        "orientations": orientations.count,
        "orientation_names": orientations.names(limit=10),
        "degree": degree,
        "degree_selection": [
            {"degree": d, "heldout_rms_mg": round(t * 1e3, 4),
             "heldout_rms_mg_xyz": [round(float(v) * 1e3, 4) for v in h]}
            for d, (t, h) in enumerate(zip(totals, heldout, strict=True))
        ],
        "heldout_rms_mg_xyz": {
            "uncompensated": [round(float(v) * 1e3, 4) for v in heldout[0]],
            "compensated": [round(float(v) * 1e3, 4) for v in chosen],
        },
        "rate_term": model.temperature_rate,
        "rate_selection": rate_tried,
        "temperature_source": model.temperature_source,
        "valid_c": [lo, hi],
        "centre_c": model.t_centre_c,
        "bias_change_mg": dict(zip(sfem.PARAM_NAMES[:3],
                                   [round(float(v) * 1e3, 4) for v in change], strict=True)),
        "bias_tempco_ug_per_c": {
            n: [round(float(v) * 1e6, 3) for v in phys[k, 1:]]
            for k, n in enumerate(sfem.PARAM_NAMES[:3])
        },
        "bias_slope_ug_per_c": _slope_report(model, captures.temperature_c()),
        "fitted": dict(model.fitted),
        "held": dict(model.held),
        "notes": list(model.notes),
    }


def _slope_report(model: ThermalModel, temperature_c: np.ndarray) -> dict[str, Any]:
    """Each fitted axis' bias slope d b/dT (Eq. 8) at the ends of the capture means'
    temperatures (``temperature_c``: where the data pin it; the valid range reaches the raw
    rows' extremes, and a cubic's slope out there is an extrapolation) and at the centre,
    µg/°C, ± 1σ with the choice of the degree in it (:func:`_selection_cov`)."""
    T = np.asarray(temperature_c, float)
    temps = np.array([np.nanmin(T), model.t_centre_c, np.nanmax(T)])
    slope, se = bias_slope_g_per_c(model, temps, with_choice=True)
    fitted = [k for k, n in enumerate(sfem.PARAM_NAMES[:3]) if n in model.fitted]
    # an axis fitted absolutely (two or more orientations) has standard errors of its
    # coefficients only, no covariance: its slope's error is not given (null), not 0
    return {"temperature_c": [round(float(t), 3) for t in temps],
            **{sfem.PARAM_NAMES[k]: {"value": [round(float(v) * 1e6, 3) for v in slope[k]],
                                     "stderr": [round(float(v) * 1e6, 3) if np.isfinite(v)
                                                else None for v in se[k]]}
               for k in fitted}}


def _format_slopes(slopes: dict[str, Any] | None) -> list[str]:
    axes = {k: v for k, v in (slopes or {}).items() if k != "temperature_c"}
    if not axes:
        return []
    temps = " / ".join(f"{t:.2f}" for t in slopes["temperature_c"])  # type: ignore[index]
    return [f"bias slope at {temps} °C (µg/°C, ± 1σ with the choice of degree): "
            + "; ".join(f"{n} " + " / ".join(
                f"{v:+.1f}" + ("" if e is None else f" ± {e:.1f}")
                for v, e in zip(d["value"], d["stderr"], strict=True))
                + (" (fitted absolutely: its error is the absolute fit's)" if None in d["stderr"]
                   else "")
                for n, d in axes.items())]


def format_warmup(report: dict[str, Any]) -> str:
    """The warm-up report as text: what was fitted and held, and the held-out error."""
    lo, hi = report["valid_c"]
    lines = [
        f"warm-up calibration of {report['recording']}: {report['captures']} capture means, "
        f"{report['orientations']} orientation(s) ({report['orientation_names']})",
        f"temperature {report['temperature_source']} {lo:.2f} .. {hi:.2f} °C "
        f"(valid range: the data's span)",
        f"degree {report['degree']} chosen by held-out error (RMS of held-out captures "
        "x/y/z, mg): "
        + ", ".join(f"d={s['degree']}: " + "/".join(f"{v:.4f}" for v in s["heldout_rms_mg_xyz"])
                    for s in report["degree_selection"]),
        "held-out RMS per axis x, y, z (mg): uncompensated "
        + " ".join(f"{v:.4f}" for v in report["heldout_rms_mg_xyz"]["uncompensated"])
        + "; compensated "
        + " ".join(f"{v:.4f}" for v in report["heldout_rms_mg_xyz"]["compensated"]),
        "bias change over the valid range (mg): "
        + ", ".join(f"{k} {v:+.4f}" for k, v in report["bias_change_mg"].items()),
        *_format_slopes(report.get("bias_slope_ug_per_c")),
        "fitted: " + (", ".join(report["fitted"]) or "nothing (no change with temperature "
                                                       "above the noise)"),
        *_format_absolute(report.get("absolute")),
        *_format_norm_rmse(report),
        "held: " + "; ".join(f"{k}" for k in report["held"])
        + " (" + "; ".join(sorted(set(report["held"].values()))) + ")",
    ]
    return "\n".join(lines)


def _format_norm_rmse(report: dict[str, Any]) -> list[str]:
    """The |g| error line (Eq. 9) with what it measures (:func:`norm_rmse_caveat`)."""
    if report.get("rmse_before_mg") is None or report.get("rmse_after_mg") is None:
        return []
    caveat = norm_rmse_caveat(report, "the held-out RMS above")
    return [f"|g| error (Eq. 9, RMS over the capture means of |reading| - g, mg): before "
            f"{report['rmse_before_mg']:.4f}, after {report['rmse_after_mg']:.4f}"
            + (f"; {caveat}" if caveat else "")]


def norm_rmse_caveat(report: dict[str, Any], fit_figure: str) -> str | None:
    """What a warm-up report's |g| error before/after is not, for a person reading it (the
    CLI's report, the dashboard's calibration page): None when the orientations identify
    every bias and scale. ``fit_figure`` names where the fit's own figure is shown."""
    unknown = [n for n in ("bx", "by", "bz", "sx", "sy", "sz")
               if n not in ((report.get("absolute") or {}).get("parameters") or {})]
    if not unknown:
        return None
    return (f"not a figure of the fit: it contains the constant part of {', '.join(unknown)}, "
            "which a warm-up does not identify, and 'after' moves with the temperature the "
            f"bias change is referred to (centre_c); the fit's figure is {fit_figure}")


def _format_absolute(absolute: dict[str, Any] | None) -> list[str]:
    """The report lines of the parameters fitted absolutely (none without)."""
    if not absolute or not absolute["parameters"]:
        return []
    shown = []
    for n, p in absolute["parameters"].items():
        scale, unit = (1e3, "mg") if p["unit"] == "g" else \
            (1e6, "ppm") if p["unit"] == "1" else (1e3, "mrad")
        value = p["value"] - (1.0 if p["unit"] == "1" else 0.0)
        label = f"{n}-1" if p["unit"] == "1" else n
        shown.append(f"{label} {value * scale:+.4g} ± {p['stderr'] * scale:.2g} {unit}")
    return [f"absolute at centre_c ({absolute['mode']} mode, degree {absolute['degree']} in "
            f"T; residual RMS {absolute['residual_rms_ug']:.1f} µg): " + ", ".join(shown)]


def _span_said(captures: Recording, temperature_c: np.ndarray) -> str:
    """How long and how far the readings go by their times: a log read with a wrong time
    unit or --rate-hz is ten or a thousand times too short, which "record a longer
    warm-up" alone would not tell its owner."""
    span_s = float(np.ptp(captures.t_s)) if len(captures) else 0.0
    if span_s <= 0.0:
        return ""
    dT = float(np.ptp(temperature_c))
    return (f"; its capture means span {span_s:.3g} s and {dT:.3g} °C "
            f"({dT / span_s * 60.0:.3g} °C/min): if the log ran longer, its time unit or "
            f"--rate-hz was read wrong (soakcal import's summary says `over … s`)")
