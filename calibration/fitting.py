"""The one way to calibrate a recording: :func:`fit` → :class:`CalibrationFit`.

``soakcal calibrate`` (calibration/cli.py), the service's fitting phase
(service/engine/calibrate.py), its figure refits and the benchmarks all call
:func:`fit`, so the same data gets the same answer everywhere. In order:

1. the rows are read as capture means (:func:`calibration.captures.capture_means`);
2. where the die stood still, steps (:func:`calibration.plateaus.segment_recording`:
   declared soaks at a held setpoint are steps, rows on no plateau are continuous);
3. the gate decides what the orientations identify (:func:`calibration.gate.plan`):
   ``sfem`` (the SFEM per step, Eq. 4–7, and its cubic in temperature, Eq. 8:
   :mod:`calibration.thermal`), ``continuous`` (the SFEM at each reading's own die
   temperature: :mod:`calibration.continuous`) or ``warmup`` (each axis' bias change
   with temperature, and what 2 or more orientations determine absolutely:
   :mod:`calibration.warmup`), or refuses;
4. the fit, and the gate's physical checks on its result
   (:func:`calibration.gate.check_model`), so no caller gets a model the gate refuses;
5. the local gravity used, and why it is an input, in the model and the report.

The result is one typed, frozen record in the spirit of scipy's ``OptimizeResult``:
what was fitted and held, the parameters with their units and standard errors, the
RMSE (Eq. 9) and the residuals, the valid range, the mode, the solver's convergence,
message and evaluations. It carries the report and the step rows that
:mod:`calibration.report`, :mod:`calibration.holdout` and the demo read.

Errors are :class:`calibration.errors.CalibrationError` with one line saying why
and what data would fix it (:class:`calibration.gate.GateRefusal`,
:class:`calibration.errors.NotIdentifiable`, :class:`OptionNotApplicable`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from calibration import gate, sfem
from calibration.captures import Captures, capture_means
from calibration.errors import CalibrationError
from calibration.gravity import NOT_IDENTIFIABLE_NOTE, LocalGravity
from calibration.plateaus import segment_recording
from calibration.recording import Recording
from calibration.thermal import DEFAULT_METHOD, METHODS, StepResult, ThermalFit, ThermalModel

Kind = Literal["sfem", "continuous", "warmup"]
# Units of the 12 SFEM parameters (Eq. 1): bias in g, scale dimensionless, angles in rad.
PARAM_UNITS = ("g",) * 3 + ("1",) * 3 + ("rad",) * 6


class OptionNotApplicable(CalibrationError):
    """An option the gate's decision cannot use (``option`` names it; the message says why)."""

    def __init__(self, option: str, message: str) -> None:
        super().__init__(message)
        self.option = option


@dataclass(frozen=True)
class FitOptions:
    """How to fit. ``method`` None: the default (``joint``) with no note; given, a
    continuous fit says it applies to step fits only."""

    method: str | None = None  # "per_step" | "joint" (step fits)
    degree: int = 3  # the step fit's polynomial degree in temperature (Eq. 8)
    gravity: LocalGravity | None = None  # None: the references' median |g|, or 1 g
    rate_gain_ug_per_c_per_min: tuple[float, float, float] | None = None  # measured k (x,y,z)


@dataclass(frozen=True)
class ParameterEstimate:
    """One SFEM parameter (Eq. 1) as a polynomial in (T − centre_c) (Eq. 8).

    ``coeffs[j]`` is in ``unit``/°C^j; ``stderr[j]`` its standard error (NaN where not
    fitted). A temperature-independent model has one coefficient.
    """

    name: str
    unit: str  # of the parameter itself: "g", "1" or "rad"
    fitted: bool
    why: str  # "fitted", or why it was held and at what
    coeffs: tuple[float, ...]
    stderr: tuple[float, ...]

    @property
    def value(self) -> float:
        """At the model's centre temperature."""
        return self.coeffs[0]


@dataclass(frozen=True)
class CalibrationFit:
    """Everything one calibration produced (scipy's ``OptimizeResult``, named and typed)."""

    kind: Kind  # what the gate decided: sfem | continuous | warmup
    mode: str  # residuals: "reference" (3 per reading) | "norm" (|g|, Eq. 3) | "warmup"
    method: str  # "joint" | "per_step" | "continuous" | "warmup"
    reason: str  # the gate's one line: why this kind
    orientations: int  # distinct orientations in the recording (calibration.gate)
    model: ThermalModel  # ready to compensate; what `calibrate -o` writes
    parameters: tuple[ParameterEstimate, ...]  # the 12 of Eq. 1, with units
    fitted: dict[str, str]
    held: dict[str, str]
    valid_c: tuple[float, float] | None  # None: temperature-independent
    rmse_ug: float  # Eq. 9 after the model (module docstring of each kind), µg
    residuals_ug: np.ndarray  # per used row: |compensated| − g (sfem, continuous), µg;
    #                           warm-up: per axis, the capture less its orientation's mean
    converged: bool
    message: str
    nfev: int  # residual evaluations of the fits that made the model (continuous: the last)
    notes: tuple[str, ...]
    report: dict[str, Any]  # the JSON report `calibrate --json` prints (model_file aside)
    recording: Recording  # the capture means that were fitted
    # What calibration.report / calibration.holdout / the demo read (ThermalFit's names):
    steps: tuple[StepResult, ...] = ()  # Table 6 rows (sfem only)
    row_temperature_c: np.ndarray = field(default_factory=lambda: np.zeros(0))
    row_step: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    raw_used_g: np.ndarray | None = None  # the rows the fit used, when not the recording's


def fit(recording: Recording, options: FitOptions | None = None) -> CalibrationFit:
    """Calibrate ``recording`` (module docstring); raises CalibrationError with the reason."""
    opts = options or FitOptions()
    method = opts.method or DEFAULT_METHOD
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    gate.check_recording(recording)  # a recording that contradicts itself
    caps = capture_means(recording)
    captures = caps.recording
    # the captures' distinct orientations, clustered once for the steps, the gate and the fit
    ori = gate.distinct_orientations(captures.raw_g, captures.sigma_g)
    seg = segment_recording(captures, ori.labels)  # steps only where the die stood still
    decided = gate.plan(captures, continuous=seg.is_continuous, orientations=ori,
                        source=recording)
    k = None if opts.rate_gain_ug_per_c_per_min is None else np.asarray(
        opts.rate_gain_ug_per_c_per_min, float)
    g_local = None if opts.gravity is None else opts.gravity.g
    if decided.kind == "warmup":
        return _warmup(recording, caps, decided, k, opts.gravity)
    if decided.kind == "continuous":
        from calibration.continuous import fit_continuous

        tf = fit_continuous(captures, seg, g_local=g_local, rate_gain_ug_per_c_per_min=k,
                            orientation=ori.labels)
        gate.check_model(tf.model, captures, tf.row_temperature_c)
        _say_air_only(tf, captures, seg.continuous_rows)
        if opts.method:
            note = (f"--method {opts.method} applies to step fits; this recording has rows "
                    "on no plateau and was fitted continuously")
            tf.notes.append(note)
            tf.report["notes"].append(note)
    else:
        from calibration.thermal import fit_campaign  # gated inside

        tf = fit_campaign(captures, method=method, degree=opts.degree, g_local=g_local,
                          rate_gain_ug_per_c_per_min=k)
    tf.notes[:0] = caps.notes + [decided.reason]
    tf.report["notes"][:0] = caps.notes + [decided.reason]
    tf.report["orientations"] = decided.orientations.count
    tf.model.notes[:0] = caps.notes
    _record_gravity(tf, opts.gravity)
    return _from_thermal(tf, decided, captures)


AIR_ONLY_NOTE = (
    "only chamber_c (the air) was recorded on {n} row(s) where the chamber moved: the die "
    "lags the air by its time constant × the ramp rate, unknown without the die's own "
    "channel, so this model's temperatures are the air's (off by that lag, with opposite "
    "signs on heating and cooling), and a rate sensitivity k fitted from the legs holds the "
    "lag, not the sensor's own k; its residuals do not bound its error at rest: record "
    "sensor_c (the die temperature) on a ramp, or soak")


def _say_air_only(tf: ThermalFit, captures: Recording, continuous_rows: int) -> None:
    """A continuous fit on the chamber air alone cannot know the die temperature: say so
    plainly (note and 'not identified'), as the gate says what orientations cannot fix."""
    if captures.temperature_source != "chamber_c" or continuous_rows == 0:
        return
    note = AIR_ONLY_NOTE.format(n=continuous_rows)
    tf.notes.append(note)
    tf.model.notes.append(note)
    tf.report.setdefault("notes", []).append(note)
    ident = tf.report.get("identified")
    if isinstance(ident, dict):
        no = ident.setdefault("not_identified", [])
        no.append("the die temperature of the rows where the chamber moved (only chamber_c): "
                  "the model is the sensor against the air, not the die")
        # a k fitted from the legs is the lag seen through the tempco, not the sensor's own
        for line in [x for x in ident.get("identified", []) if x.startswith("rate sensit")]:
            ident["identified"].remove(line)
            no.append("the sensor's own rate sensitivity and hysteresis: with only the air's "
                      "temperature, the heating and cooling legs' difference is mostly the die "
                      "lag (" + line.split(" from the heating")[0] + ")")


def rmse_after_ug(steps: tuple[StepResult, ...] | list[StepResult]) -> float:
    """Campaign RMSE after the thermal model (Eq. 9): rms over steps of the per-step values."""
    vals = [st.rmse_polynomial_ug for st in steps if math.isfinite(st.rmse_polynomial_ug)]
    return float(np.sqrt(np.mean(np.square(vals)))) if vals else math.nan


# --- the three kinds --------------------------------------------------------------
def _from_thermal(tf: ThermalFit, decided: gate.Plan, captures: Recording) -> CalibrationFit:
    model = tf.model
    used = tf.row_step >= 0
    raw = captures.raw_g if tf.raw_used_g is None else tf.raw_used_g
    temp = np.nan_to_num(tf.row_temperature_c[used], nan=model.t_centre_c)
    cal = model.compensate(raw[used], temp, extrapolate=True)
    residuals = (np.linalg.norm(cal, axis=1) - model.g_local) * 1e6
    steps = tuple(tf.steps)
    status = tf.status
    continuous = decided.kind == "continuous"
    return CalibrationFit(
        kind="continuous" if continuous else "sfem", mode=model.mode, method=model.method,
        reason=decided.reason, orientations=decided.orientations.count, model=model,
        parameters=parameters(model), fitted=dict(model.fitted), held=dict(model.held),
        valid_c=model.valid_c,
        rmse_ug=float(np.sqrt(np.mean(residuals**2))) if continuous else rmse_after_ug(steps),
        residuals_ug=residuals, converged=status.converged, message=status.message,
        nfev=status.nfev, notes=tuple(tf.notes), report=tf.report, recording=captures,
        steps=steps, row_temperature_c=tf.row_temperature_c, row_step=tf.row_step,
        raw_used_g=tf.raw_used_g)


def _warmup(recording: Recording, caps: Captures, decided: gate.Plan,
            rate_gain: np.ndarray | None, gravity: LocalGravity | None = None
            ) -> CalibrationFit:
    """Too few orientations for the SFEM: each axis' bias change with temperature, and
    what 2 or more orientations determine absolutely (:mod:`calibration.warmup_absolute`)
    with |g| the local gravity (``gravity``; default 1 g, or the references' median).
    ``caps``: ``recording``'s capture means; where they are raw samples, what those say of
    each capture mean's temperature noise is dT/dt's noise for the rate check
    (:func:`calibration.captures.own_temperature_noise`), unless the temperature is
    rebuilt from a coarse channel."""
    from calibration.captures import own_temperature_noise, warmup_rebuild
    from calibration.export_firmware import firmware_reading_record, quantised_reading_lines
    from calibration.firmware_polynomial import quantised_reading_error, rate_fold_record
    from calibration.rebuild_rate_noise import rebuild_rate_noise
    from calibration.unresolved_temperature import note as unresolved_note
    from calibration.unresolved_temperature import unresolved_record
    from calibration.warmup import fit_warmup

    if rate_gain is not None:
        raise OptionNotApplicable(
            "rate_gain_ug_per_c_per_min",
            f"not applied to a warm-up ({decided.reason.split(':')[0]}); the bias change "
            f"fitted includes it")
    captures, capture_notes = caps.recording, caps.notes
    temp = recording.temperature_c()
    if gravity is not None:
        g_local = gravity.g
    elif captures.has_reference:
        g_local = float(np.median(np.linalg.norm(captures.ref_g, axis=1)))
    else:
        g_local = 1.0
    # a coarsely quantised channel: the die temperature rebuilt from its steps' transitions,
    # for the fit, its held-out and rate checks, and the figures below alike
    means = captures
    captures, dq = warmup_rebuild(captures)
    rebuilt = None if dq is None else dq.note()
    if rebuilt:
        capture_notes = [*capture_notes, rebuilt]
    # dT/dt's noise on a rebuilt temperature includes the rebuild's own error
    noise = None if dq is None else rebuild_rate_noise(captures.t_s, dq, means.columns.get("n"))
    # where the die rested or turned inside a step the rebuilt temperature is a guess: said,
    # with the bound (unresolved_temperature.py says why the readings stay in the fit)
    unresolved = unresolved_record(captures, dq)
    if unresolved:
        capture_notes = [*capture_notes, unresolved_note(unresolved)]
    # a rebuilt temperature is no capture's mean: its own samples do not say its noise
    own_noise = None if dq is not None else own_temperature_noise(recording, caps)
    wf = fit_warmup(captures, decided.orientations,
                    span_c=(float(np.min(temp)), float(np.max(temp))), g_local=g_local,
                    rebuild_noise=noise, own_noise=own_noise)
    gate.check_model(wf.model, captures)
    # the orientations the fit used: a drifting board's clusters joined (warmup.py)
    orientations = wf.orientations
    reason = decided.reason if wf.joined_note is None else (
        f"{decided.reason}; the fit joins them: {wf.joined_note}")
    if wf.absolute is not None and wf.absolute.capture_residual_g.size:
        gate.check_warmup_residuals(wf.absolute.capture_residual_g, orientations,
                                    wf.absolute.names + tuple(wf.absolute.loose))
    if rebuilt and wf.model.temperature_rate:
        # the rebuilt temperature's error is largest where the die turns, where dT/dt
        # changes sign: a rate term can hold some of it as well as the part's physics
        said = ("the rate term was fitted on the rebuilt temperature of a quantised channel: "
                "besides a rate-sensitive part or a lagging channel it may hold part of the "
                "rebuild's error where the die turns (kept because held-out error prefers it)")
        wf.model.notes.append(said)
        wf.report["notes"].append(said)
    wf.model.notes[:0] = capture_notes
    wf.report["notes"][:0] = capture_notes + [reason]
    model = wf.model
    wf.report["unresolved_temperature"] = unresolved
    T = captures.temperature_c()
    heldout_mg = wf.report.get("heldout_rms_mg_xyz", {}).get("compensated")
    rebuilt_read = dq is not None and dq.read_c is not None
    if rebuilt_read:
        # what a firmware that reads the raw channel makes of a model fitted in the rebuilt
        # temperature, on this log (fitted in firmware_polynomial.py; the exports say it)
        firmware = quantised_reading_error(
            model, dq.read_c, T, dq.lsb_c, heldout_mg,
            t_s=captures.t_s, level_c=dq.level_c, dither_lsb=dq.dither_lsb)
        model.provenance["quantised_temperature"] = firmware
        wf.report["quantised_temperature"] = firmware
    if model.temperature_rate:
        # neither firmware applies a rate term: the export folds its mean at each reading
        # into the polynomial (firmware_polynomial.rate_fold_record), fitted here on this log
        fold = rate_fold_record(
            model, captures.t_s, dq.read_c if rebuilt_read else T, T, heldout_mg,
            lsb_c=dq.lsb_c if rebuilt_read else 0.0,
            level_c=dq.level_c if rebuilt_read else None,
            dither_lsb=dq.dither_lsb if rebuilt_read else 0.0,
            reading_record=firmware if rebuilt_read else None)
        model.provenance["rate_fold"] = fold
        wf.report["rate_fold"] = fold
    if rebuilt_read:
        said = quantised_reading_lines(firmware_reading_record(model))
        wf.report["notes"] += [f"firmware export: {line}" for line in said]
    comp = captures.raw_g - model.params_vector_at(T, extrapolate=True)[:, sfem.BIAS]
    labels = orientations.labels
    means = np.zeros((orientations.count, 3))
    np.add.at(means, labels, comp)
    means /= np.bincount(labels, minlength=means.shape[0])[:, None]
    residuals = (comp - means[labels]) * 1e6
    _add_norm_figures(wf.report, captures.raw_g, model.compensate(captures.raw_g, T, True), T,
                      g_local, labels)
    return CalibrationFit(
        kind="warmup", mode="warmup", method="warmup", reason=reason,
        orientations=orientations.count, model=model, parameters=parameters(model),
        fitted=dict(model.fitted), held=dict(model.held), valid_c=model.valid_c,
        rmse_ug=float(np.sqrt(np.mean(residuals**2))), residuals_ug=residuals,
        converged=True, message="linear least squares (closed form)", nfev=0,
        notes=tuple(wf.report["notes"]), report=wf.report, recording=captures,
        row_temperature_c=T, row_step=np.zeros(len(captures), int))


def _add_norm_figures(report: dict[str, Any], raw_g: np.ndarray, cal_g: np.ndarray,
                      row_c: np.ndarray, g_local: float, orient: np.ndarray) -> None:
    """A warm-up's |g| error (Eq. 9) before and after its model, overall and per temperature
    band (:func:`calibration.ramp_report.temperature_bands`), as a ramp's report has them:
    what a reader compares across the three kinds. After includes what the warm-up could
    not identify (a constant bias, a scale the orientations do not see)."""
    from calibration.ramp_report import norm_rmse_mg, temperature_bands

    report.update(norm_rmse_mg(raw_g, cal_g, g_local))
    report["bands"] = [b for _, b in temperature_bands(row_c, raw_g, cal_g, g_local, orient)]


def parameters(model: ThermalModel) -> tuple[ParameterEstimate, ...]:
    """The model's 12 parameters in physical units per °C^j, fitted or held and why."""
    coeffs = model.physical_coeffs()
    scale = model.t_scale_c ** np.arange(model.degree + 1)
    se = (np.full_like(coeffs, np.nan) if model.coeff_stderr is None
          else model.coeff_stderr / scale[None, :])
    out = []
    for k, name in enumerate(sfem.PARAM_NAMES):
        fitted = name in model.fitted
        out.append(ParameterEstimate(
            name=name, unit=PARAM_UNITS[k], fitted=fitted,
            why=model.fitted[name] if fitted else model.held.get(name, "held"),
            coeffs=tuple(float(v) for v in coeffs[k]),
            stderr=tuple(float(v) for v in se[k])))
    return tuple(out)


def _record_gravity(tf: ThermalFit, gravity: LocalGravity | None) -> None:
    """Say in the model file and the report which local gravity was used and why it is input."""
    g = gravity or LocalGravity(
        tf.model.g_local,
        "default: magnitude of the reference vectors (median)" if tf.model.mode == "reference"
        else "default; set it with --gravity-g or --latitude-deg/--height-m")
    tf.model.provenance["gravity"] = g.to_dict()
    tf.report["gravity"] = {**g.to_dict(), "identifiable": False, "why": NOT_IDENTIFIABLE_NOTE}
    note = f"local gravity {g.g:.6f} g ({g.source}); {NOT_IDENTIFIABLE_NOTE}"
    tf.model.notes.append(note)
    tf.notes.append(note)
    tf.report.setdefault("notes", []).append(note)
