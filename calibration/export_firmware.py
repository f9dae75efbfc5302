"""Parameter files for the autopilots people fly: PX4 ``TC_A*`` and ArduPilot ``INS_TCAL*``.

Both firmwares correct an accelerometer for temperature with an *offset-only* cubic,
subtracted from the reading in m/s² in the sensor frame before the ordinary
calibration's offsets and scales (read from their application code):

* PX4 (``TemperatureCompensation::calc_thermal_offsets_3D``, applied in
  ``calibration::Accelerometer::Correct``): ``out = R · ((raw − o(T) − CAL_OFF) ⊙
  CAL_SCALE)`` with ``o_i(T) = X0_i + X1_i·d + X2_i·d² + X3_i·d³``, ``d = clamp(T, TMIN,
  TMAX) − TREF``, coefficients in m/s²/°C^j. There is no thermal scale (the
  ``TC_A*_SCL_*`` of early releases is gone).
* ArduPilot (``AP_InertialSensor::TCal::correct_sensor``, before ``INS_ACCOFFS`` and
  ``INS_ACCSCAL``): ``v −= P(clamp(T) − 35) − P(clamp(T_cal) − 35)`` with ``P(d) =
  (ACC1·d + ACC2·d² + ACC3·d³)·1e−6`` m/s², 35 °C a fixed reference in the firmware
  (no parameter), ``T_cal`` the temperature of the ordinary accelerometer calibration
  (``INS_ACCn_CALTEMP``). No constant term: the offset at ``T_cal`` is ``INS_ACCOFFS``.

soakcal's model is ``out = A(T) · (raw − b(T))`` (seed Eq. 1 with Eq. 8): the export
writes ``b(T)`` (× g in m/s²) and reports what it leaves out: ``A(T) − I`` (scale
factors, non-orthogonality, misalignment and their temperature change), as the
largest error that costs at |a| ≤ 1 g over the valid range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import Polynomial

from calibration import sfem
from calibration.errors import ModelFileError
from calibration.firmware_flight import (
    ARDUPILOT_TEMP_CUTOFF_HZ,
    PX4_POLL_PERIOD_S,
    PX4_UPDATE_GATE_C,
    ardupilot_filter_delay_s,
)
from calibration.firmware_polynomial import (
    FIRMWARE_DEGREE,
    at_rest_figures,
    file_bias_x_g,
)
from calibration.thermal import ThermalModel

STANDARD_GRAVITY_M_S2 = 9.80665  # PX4 CONSTANTS_ONE_G and ArduPilot GRAVITY_MSS
ARDUPILOT_TEMP_REFERENCE_C = 35.0  # TEMP_REFERENCE in AP_InertialSensor_tempcal.cpp
ARDUPILOT_SCALE_FACTOR = 1.0e6  # SCALE_FACTOR there: parameters are 1e6 × m/s²/°C^j
ARDUPILOT_TEMP_LIMITS_C = (-70.0, 80.0)  # INS_TCALn_TMIN/TMAX @Range
PX4_PARAM_INT32, PX4_PARAM_REAL32 = 6, 9  # MAV_PARAM_TYPE in QGroundControl .params files


# The firmware's error from reading its own quantised channel is said LOUDLY (first in the
# header, "WARNING" on stderr) when its RMS on the fit log exceeds the fit's own held-out
# RMS on some axis by this factor: the firmware then does several times worse than the
# model soakcal fitted, and a lab engineer must know before flying it.
LOUD_FACTOR = 3.0


@dataclass
class FirmwareExport:
    """The parameter file text and the one-line limitations for stderr."""

    text: str
    limitations: list[str]
    # what the firmware does with its own (quantised) temperature reading, for a model
    # fitted in a rebuilt temperature (quantised_reading_lines); "WARNING: ..." when loud
    reading: list[str] = field(default_factory=list)



def _xyz(v: object) -> str:
    """Three figures x / y / z, mg to the µg, as every header line writes them."""
    return " / ".join(f"{x:.3f}" for x in v)  # type: ignore[attr-defined]

def bias_polynomials_m_s2(model: ThermalModel, t_ref_c: float,
                          bias_x_g: np.ndarray | None = None) -> np.ndarray:
    """(3, 4): bias b_i(T) in m/s² as Σ_j c_ij (T − t_ref)^j: an exact re-expansion of the
    model's Eq. 8 bias, or of ``bias_x_g`` ((3, m+1), g, in the model's x = (T − centre) /
    scale: the file's polynomial, :func:`calibration.firmware_polynomial.file_bias_x_g`)."""
    shift = Polynomial([(t_ref_c - model.t_centre_c) / model.t_scale_c, 1.0 / model.t_scale_c])
    coeffs = model.coeffs[sfem.BIAS] if bias_x_g is None else np.asarray(bias_x_g, float)
    out = np.zeros((3, FIRMWARE_DEGREE + 1))
    for i in range(3):
        poly = Polynomial(coeffs[i])(shift)
        c = poly.coef * STANDARD_GRAVITY_M_S2
        out[i, : c.size] = c
    return out


def quantised_reading_lines(record: dict[str, object] | None) -> list[str]:
    """The lines an export says about a model fitted in a rebuilt temperature (none for a
    model without the record): which temperature the file's polynomial is in, and what it
    costs at the firmware's own quantised reading."""
    if not record:
        return []
    rms, peak = record["rms_mg"], record["peak_mg"]
    step = record["tempco_lsb_mg"]
    q = float(record["lsb_c"])  # type: ignore[arg-type]
    fit = record.get("fit_heldout_mg")
    in_reading = record.get("raw_reading_bias_x_g") is not None

    per_sample = bool(record.get("per_sample"))
    rate = record.get("rate_term_rms_mg")
    whose = ("the model's whole offset at the rebuilt temperature" if rate is not None
             else "the offset at the rebuilt temperature")
    how = ""
    if per_sample:
        how = (f", p evaluated at each sample's own reading as a firmware that reads it per "
               f"sample does (ArduPilot's unfiltered IMU drivers; PX4 holds the offset of "
               f"one poll's reading: see its update gate) (at the capture mean of the reading "
               f"instead, as a firmware that low-pass filters its reading evaluates it: RMS "
               f"{_xyz(record['smoothed_rms_mg'])} mg)")
    dropped = ""
    folded = bool(record.get("rate_folded"))
    if folded:
        whose = "the model's whole offset (rate term included) at the rebuilt temperature"
        dropped = (f"; this includes what the polynomial cannot follow of the model's rate "
                   f"term k(T)*dT/dt, whose mean at each reading it folds in (the term alone: "
                   f"RMS {_xyz(rate)} mg on the fit log; see FOLDED below)")
    elif rate is not None and max(rate) > 0:  # type: ignore[arg-type]
        dropped = (f"; this includes the model's rate term k(T)*dT/dt, which the firmware "
                   f"cannot apply (alone RMS {_xyz(rate)} mg on the fit log)")
    of = ("the model's whole offset b + k*dT/dt" if folded else "the model's offset")
    if in_reading:
        main = (f"the model was fitted in the die temperature rebuilt from a {q:g} degC "
                f"channel, and the firmware evaluates its offset at its own {q:g} degC "
                f"reading: this file's polynomial is in that reading, the least-squares fit "
                f"over the fit log's {record['readings']} capture means of {of} "
                f"at the rebuilt temperature against the reading clamped to TMIN..TMAX (the "
                f"model's own b(T) evaluated at the reading instead: RMS "
                f"{_xyz(record['model_at_raw_rms_mg'])} mg); on the fit log it differs from "
                f"{whose} by RMS {_xyz(rms)} mg, peak {_xyz(peak)} mg (x / y / z){how}"
                f"{dropped}; the offset steps by up to {_xyz(step)} mg at each change of the "
                f"reading (tempco x LSB)")
        why = "and this file's polynomial is already the least-squares one in it"
    else:
        main = (f"the model was fitted in the die temperature rebuilt from a {q:g} degC "
                f"channel, but the firmware evaluates it at its own {q:g} degC reading: on "
                f"the fit log ({record['readings']} capture means) that differs from "
                f"{whose} by RMS {_xyz(rms)} mg, peak {_xyz(peak)} "
                f"mg (x / y / z){how}{dropped}; the offset steps by up to {_xyz(step)} mg at "
                f"each change of the reading (tempco x LSB)")
        why = ("a fit on the step values, as PX4's and ArduPilot's scripts make, does about "
               "as well")
    if fit is None:
        return [main]
    ratio = float(record.get("ratio_to_fit", 0.0))  # type: ignore[arg-type]
    versus = (f"the fit's own held-out RMS is {_xyz(fit)} mg (the file's error on such data "
              f"is then at most the sum of the two, about their root-sum-square when they "
              f"are unrelated)")
    if ratio >= LOUD_FACTOR:
        return [f"WARNING: the firmware's {q:g} degC temperature reading will cost up to "
                f"{ratio:.1f} x the fit's own error: {main}; {versus}. No parameter file removes "
                f"it (the firmware's offset is a function of that reading only; {why}); "
                f"a finer temperature channel in the firmware would, or `soakcal "
                f"compensate`, which rebuilds the temperature"]
    return [f"{main}; {versus}"]


def _check(model: ThermalModel, firmware: str) -> tuple[float, float]:
    if model.extensions:
        kinds = ", ".join(str(e.get("kind")) for e in model.extensions)
        raise ModelFileError(f"model field 'extensions': {firmware} cannot express {kinds}; "
                             "export a model from `soakcal calibrate`")
    if model.valid_c is None:
        raise ModelFileError(f"model has no temperature dependence: nothing for {firmware}'s "
                             "thermal compensation; calibrate a recording with a temperature")
    if model.temperature_source != "sensor_c":
        raise ModelFileError(
            f"model fitted on {model.temperature_source} (not the sensor's own temperature); "
            f"{firmware} compensates with the IMU's temperature reading: calibrate a "
            "recording with sensor_c")
    if model.degree > FIRMWARE_DEGREE:
        raise ModelFileError(f"model degree {model.degree}: {firmware}'s offset polynomial is "
                             f"cubic; calibrate with degree <= {FIRMWARE_DEGREE}")
    lo, hi = model.valid_c
    return float(lo), float(hi)


def left_out(model: ThermalModel, n_temps: int = 41,
             fold: dict[str, object] | None = None) -> list[str]:
    """What an offset-only export cannot express, each with the error it costs (mg at 1 g);
    ``fold``: the figures of the file's folded rate term (default: the model's
    ``rate_fold`` record, the per-sample file; :func:`filtered_fold_record` for the
    ArduPilot file fitted at the filtered reading)."""
    lo, hi = model.valid_c or (0.0, 0.0)
    temps = np.linspace(lo, hi, n_temps)
    P = model.params_vector_at(temps, extrapolate=True)
    A = sfem.matrix_from_vector(P)  # (n,3,3)
    dev = A - np.eye(3)
    err_mg = float(np.max(np.linalg.norm(dev, ord=2, axis=(1, 2)))) * 1e3
    out: list[str] = []
    s = P[:, sfem.SCALE]
    s_mid = s[n_temps // 2]
    if np.max(np.abs(s_mid - 1.0)) > 0:
        out.append("scale factors (" + ", ".join(
            f"s{c}-1 {(v - 1.0) * 1e6:+.0f} ppm" for c, v in zip("xyz", s_mid, strict=True))
            + " at mid-range)")
    ds = np.max(np.ptp(s, axis=0)) * 1e6
    if ds > 0:
        out.append(f"scale change with temperature (up to {ds:.0f} ppm over the range)")
    ang = np.max(np.abs(P[:, 6:12])) * 1e3
    if ang > 0:
        out.append(f"non-orthogonality and misalignment (up to {ang:.3f} mrad)")
    if out:
        out.append(f"leaving them out costs up to {err_mg:.3f} mg at |a| <= 1 g "
                   f"over {lo:.2f} .. {hi:.2f} degC")
    if model.temperature_rate:
        fold = fold or model.provenance.get("rate_fold")
        out.append(rate_term_folded(fold) if fold and fold.get("folded_rate_x_g") is not None
                   else rate_term_dropped(model))
    held = [n for n, ok in zip(sfem.PARAM_NAMES[:3], model.identifiable[:3], strict=True)
            if not ok]
    reasons = getattr(model, "held", {}) or {}
    written = file_bias_x_g(model)
    coef = np.asarray(model.coeffs[sfem.BIAS] if written is None else written, float)
    for name in held:
        why = reasons.get(name, "not identifiable from these data")
        # said as what the file then does on that axis, read off the file's own polynomial
        flat = not np.any(coef[sfem.PARAM_NAMES.index(name), 1:])
        what = (": the file's offset on that axis does not change with temperature (no "
                "thermal compensation there)" if flat else "")
        out.append(f"{name} not fitted{what}; {why}")
    held_nominal = [n for n in getattr(model, "held", {}) if n not in sfem.PARAM_NAMES[:3]]
    if held_nominal:
        out.append(f"not calibrated by this model (held at nominal): {', '.join(held_nominal)}; "
                   "the firmware's ordinary accelerometer calibration stays in charge of them")
    return out


def rate_term_dropped(model: ThermalModel, n_temps: int = 41) -> str:
    """What dropping a warm-up's rate term k(T)·dT/dt costs: both firmwares' offsets are
    functions of T only. Its largest effect at the fit log's own rates (the model's
    ``rate_c_per_min_range``), or per °C/min for a model without that record."""
    term = model.temperature_rate or {}
    gain = np.asarray(term["gain_ug_per_c_per_min"], float)  # (3, m+1) in x
    lo, hi = model.valid_c or (model.t_centre_c, model.t_centre_c)
    x = model.x_of(np.linspace(lo, hi, n_temps))
    k = np.abs(np.array([np.polynomial.polynomial.polyval(x, g) for g in gain]))  # (3, n)
    axis = int(np.argmax(k.max(axis=1)))
    k_max = float(k.max())
    head = (f"DROPPED: the warm-up's rate term k(T)*dT/dt (|k| up to {k_max:.1f} ug per "
            f"degC/min, axis {'xyz'[axis]}): the firmware's offset is a function of T only")
    span = term.get("rate_c_per_min_range")
    if not span:
        return (f"{head}; at 1 degC/min that leaves up to {k_max:.1f} ug uncorrected (this "
                f"model does not record its log's rates)")
    r_max = float(np.max(np.abs(span)))
    effect = k.max(axis=1) * r_max
    a = int(np.argmax(effect))
    return (f"{head}; at the log's rates ({span[0]:+.3g} .. {span[1]:+.3g} degC/min) it "
            f"corrected up to {effect[a]:.1f} ug (axis {'xyz'[a]}), left uncorrected by the "
            f"firmware while the temperature changes that fast (none at rest)")


def rate_term_folded(fold: dict[str, object]) -> str:
    """What folding a warm-up's rate term into the polynomial does
    (:func:`calibration.firmware_polynomial.rate_fold_record`): right on average for
    warm-ups like the fit log, off at rest by the folded part."""

    where = {"raw": "at the firmware's raw reading",
             "filtered": ("at the capture mean of the firmware's raw reading (where the "
                          "InvenSense drivers' 1-Hz filter evaluates it)")
             }.get(str(fold.get("reading")), "in T")
    peak = f", peak {_xyz(fold['peak_mg'])} mg" if fold.get("peak_mg") is not None else ""
    per_sample = (f"; at each sample's own reading, as the ICM-42xxx and BMI088 drivers "
                  f"evaluate it: RMS {_xyz(fold['per_sample_rms_mg'])} mg"
                  if fold.get("per_sample_rms_mg") is not None else "")
    fit = fold.get("fit_heldout_mg")
    model_own = (f"; the model's own held-out RMS (blocks of the fit log held out in turn, "
                 f"as calibrate chose its degree) is {_xyz(fit)} mg: the file's error on new "
                 f"data holds both (the RMS above is the file's distance from the model, "
                 f"not from the data)"
                 if fit is not None and fold.get("reading") == "temperature" else "")
    return (f"FOLDED: the warm-up's rate term k(T)*dT/dt (the firmware's offset is a function "
            f"of T only): this file's polynomial is the least-squares fit {where} of the "
            f"model's whole offset b(T) + k(T)*dT/dt over the fit log's {fold['captures']} "
            f"capture means, as PX4's and ArduPilot's own fits on a warm-up's samples fold the "
            f"log's mean rate effect into T; on the fit log (in-sample) it differs from that "
            f"whole offset by RMS {_xyz(fold['rms_mg'])} mg{peak} (x / y / z; with the rate "
            f"term dropped: RMS {_xyz(fold['dropped_rms_mg'])} mg{per_sample}){model_own}. "
            f"It is right "
            f"on average for warm-ups like the fit log (the same rates at the same "
            f"temperatures); at a constant temperature (dT/dt = 0) it differs from the "
            f"model's static offset by the folded part: RMS {_xyz(fold['at_rest_rms_mg'])} mg, "
            f"peak {_xyz(fold['at_rest_peak_mg'])} mg over TMIN..TMAX about its mean (the mean, "
            f"{_xyz(fold['at_rest_mean_mg'])} mg, is a constant: the ordinary accelerometer "
            f"calibration measures it where the file writes no constant); `soakcal "
            f"compensate` applies the rate term itself")


def rate_fold_warning(model: ThermalModel) -> list[str]:
    """The loud line for a model read by a fine channel whose folded file is, on its fit
    log, :data:`LOUD_FACTOR` × the fit's own held-out RMS or more from the model's whole
    offset on some axis (a rebuilt channel's is said by :func:`quantised_reading_lines`
    with the folded figures); else none."""
    fold = model.provenance.get("rate_fold") or {}
    ratio = fold.get("ratio_to_fit")
    if (fold.get("folded_rate_x_g") is None or fold.get("reading") != "temperature"
            or ratio is None or float(ratio) < LOUD_FACTOR):
        return []

    return [f"WARNING: the firmware cannot apply this warm-up's rate term k(T)*dT/dt: on the "
            f"fit log the file (the term's mean at each temperature folded in) differs from "
            f"the model's whole offset by up to {float(ratio):.1f} x the fit's own held-out "
            f"RMS {_xyz(fold['fit_heldout_mg'])} mg: RMS {_xyz(fold['rms_mg'])} mg (x / y / z; "
            f"see FOLDED below). No parameter file removes it (the firmware's offset is a "
            f"function of T only); `soakcal compensate` applies the rate term"]


def firmware_reading_record(model: ThermalModel,
                            filtered: bool = False) -> dict[str, object] | None:
    """The record :func:`quantised_reading_lines` states: the model's
    ``quantised_temperature`` record, with the figures of the file that folds the rate term
    (:func:`calibration.firmware_polynomial.rate_fold_record`) where the model carries that
    fold; ``filtered``: the figures of the file fitted at the capture mean of the reading
    (:func:`calibration.firmware_polynomial.file_bias_x_g`), where the model carries it."""
    record = model.provenance.get("quantised_temperature")
    if not record:
        return record
    key = "filtered_reading_figures" if filtered else "reading_figures"
    own = record.get("filtered_reading_figures") if filtered else None
    if own:
        record = {**record, **own, "fitted_filtered": True}
    fold = model.provenance.get("rate_fold") or {}
    figures = fold.get(key)
    if not figures or fold.get("folded_rate_x_g") is None:
        return record
    return {**record, **figures, "rate_folded": True}


def filtered_fold_record(model: ThermalModel) -> dict[str, object] | None:
    """The FOLDED line's figures for the ArduPilot file fitted at the capture mean of a
    dithered channel's reading (:func:`calibration.firmware_polynomial.file_bias_x_g` with
    ``filtered``), or None where the model carries no such fold (the file is then the
    per-sample one and ``rate_fold``'s own figures are its figures). On the fit log at the
    capture mean of the reading, where the InvenSense drivers' filter evaluates it: the
    folded file's RMS and peak (``rate_fold.filtered_reading_figures``), the static
    filtered file's RMS (``quantised_temperature.filtered_reading_figures``: the rate term
    dropped), the folded file's RMS per sample; and at rest, the filtered folded part's
    figures over TMIN..TMAX (:func:`calibration.firmware_polynomial.at_rest_figures`)."""
    fold = model.provenance.get("rate_fold") or {}
    figures = fold.get("filtered_reading_figures")
    coef = fold.get("filtered_folded_rate_x_g")
    if not figures or coef is None:
        return None
    static = (model.provenance.get("quantised_temperature") or {}).get(
        "filtered_reading_figures") or {}
    return {**fold, **at_rest_figures(model, np.asarray(coef, float)), "reading": "filtered",
            "rms_mg": figures["smoothed_rms_mg"], "peak_mg": figures.get("smoothed_peak_mg"),
            "dropped_rms_mg": static.get("smoothed_rms_mg", fold["dropped_rms_mg"]),
            "per_sample_rms_mg": figures["rms_mg"]}


# ``--temperature-reading``: the reading an ArduPilot driver hands INS_TCAL. "filtered": the
# InvenSense drivers' 1-Hz low-pass (AP_InertialSensor_Invensense); "per-sample": the
# drivers that publish the reading unfiltered (Invensensev3's default-constructed filter,
# BMI088). PX4 polls the unfiltered reading (calibration.firmware_flight).
TEMPERATURE_READINGS = ("filtered", "per-sample")
FILTERED_DRIVERS = "ArduPilot's InvenSense drivers (MPU-6000/9250, ICM-2060x/20689)"
UNFILTERED_DRIVERS = "ArduPilot's ICM-42xxx (Invensensev3) and BMI088 drivers"


def ardupilot_fitted_reading(record: dict[str, object] | None,
                             temperature_reading: str = "filtered") -> list[str]:
    """The line saying which reading the ArduPilot file's polynomial is fitted at and which
    drivers it is for, for a model that carries a polynomial fitted at the capture mean of
    a dithered channel's reading (``record``: ``firmware_reading_record(model,
    filtered=True)``, whose figures are that file's); else none (both readings then give
    the same file). ``temperature_reading``: the file written (:data:`TEMPERATURE_READINGS`)."""
    if not record or not record.get("fitted_filtered"):
        return []
    if temperature_reading == "per-sample":
        return [f"this file is fitted for {UNFILTERED_DRIVERS}, which evaluate it at each "
                f"sample's reading (`--format px4`'s polynomial, re-expanded about 35 degC); "
                f"{FILTERED_DRIVERS} low-pass filter the flickering reading at "
                f"{ARDUPILOT_TEMP_CUTOFF_HZ:g} Hz: for them `--temperature-reading filtered` "
                f"writes the polynomial fitted at the capture mean of the reading (RMS "
                f"{_xyz(record['smoothed_rms_mg'])} mg there from the model's offset on the "
                f"fit log, x / y / z)"]
    return [f"this file is fitted for {FILTERED_DRIVERS}, which low-pass filter the "
            f"flickering reading at {ARDUPILOT_TEMP_CUTOFF_HZ:g} Hz: its polynomial is the "
            f"least-squares fit at the capture mean of the reading, RMS "
            f"{_xyz(record['smoothed_rms_mg'])} mg there from the model's offset on the fit "
            f"log (x / y / z); {UNFILTERED_DRIVERS} evaluate it at each sample's reading: "
            f"RMS {_xyz(record['rms_mg'])} mg; for them `--temperature-reading per-sample` "
            f"writes the polynomial fitted at that (as `--format px4`'s)"]


def _channel_lsb_c(model: ThermalModel) -> float | None:
    """The step of the temperature channel the model was calibrated from, where the model
    records one (a rebuilt coarse channel's ``quantised_temperature`` record); else None."""
    record = model.provenance.get("quantised_temperature") or {}
    lsb = record.get("lsb_c")
    return float(lsb) if lsb else None


def export_px4(model: ThermalModel, *, instance: int = 0, device_id: int = 0,
               source_name: str = "model") -> FirmwareExport:
    """A QGroundControl parameter file of ``TC_A{instance}_*`` (see module docstring)."""
    if not 0 <= instance <= 3:
        raise ModelFileError(f"PX4 has TC_A0..TC_A3; --instance {instance} is out of range")
    lo, hi = _check(model, "PX4")
    t_ref = 0.5 * (lo + hi)  # as PX4's process_sensor_caldata.py: mid-range reference
    c = bias_polynomials_m_s2(model, t_ref, file_bias_x_g(model))
    limits = left_out(model)
    reading = quantised_reading_lines(firmware_reading_record(model)) + \
        rate_fold_warning(model)
    # A warm-up identifies only the bias *change* (gravity's projection is unknown): X0
    # is then 0, as PX4's own script leaves it (~0, readings minus their median), and the
    # constant stays with the ordinary calibration's CAL_ACCn_xOFF.
    # A warm-up of a few orientations may determine every offset absolutely
    # (calibration/warmup_absolute.py: e.g. ±z with reference directions).
    fitted_absolutely = (model.provenance.get("absolute") or {}).get("parameters", [])
    absolute = bool(np.all(model.identifiable[sfem.BIAS])) and (
        model.mode != "warmup" or all(n in fitted_absolutely for n in sfem.PARAM_NAMES[:3]))
    if absolute:
        x0_note = ("X0 is the whole offset at TREF: PX4 subtracts CAL_ACCn_xOFF as well, so "
                   "set those to 0 (or zero X0 and keep the ordinary calibration's offsets)")
    else:
        c[:, 0] = 0.0
        x0_note = ("X0 = 0: this model does not identify the constant offset (a warm-up: "
                   "gravity's projection is unknown); it stays with CAL_ACCn_xOFF from "
                   "PX4's ordinary accelerometer calibration")
    if device_id == 0:
        limits.append(f"TC_A{instance}_ID is 0: PX4 applies these only to the accelerometer "
                      "whose device id matches; give --device-id (CAL_ACCn_ID)")
    a = f"TC_A{instance}"
    rows: list[tuple[str, float, int]] = [
        ("TC_A_ENABLE", 1, PX4_PARAM_INT32), (f"{a}_ID", device_id, PX4_PARAM_INT32),
        (f"{a}_TMIN", lo, PX4_PARAM_REAL32), (f"{a}_TMAX", hi, PX4_PARAM_REAL32),
        (f"{a}_TREF", t_ref, PX4_PARAM_REAL32)]
    for j in range(FIRMWARE_DEGREE + 1):
        for i in range(3):
            rows.append((f"{a}_X{j}_{i}", float(c[i, j]), PX4_PARAM_REAL32))
    head = _header(
        f"PX4 accelerometer thermal compensation from {source_name} (soakcal export)",
        ["offset_i(T) = X0_i + X1_i*d + X2_i*d^2 + X3_i*d^3 in m/s^2, "
         "d = clamp(T, TMIN, TMAX) - TREF; subtracted from sensor_accel x/y/z (i = 0, 1, 2)",
         "T is the accelerometer's own temperature reading (sensor_accel.temperature)",
         "outside TMIN..TMAX the firmware holds the offset at the edge value (clamp)",
         px4_update_gate(c, lo, hi, t_ref, _channel_lsb_c(model)), x0_note],
        limits, reading)
    body = "\n".join(f"1\t1\t{n}\t{_num(v, t)}\t{t}" for n, v, t in rows)
    text = head + "# Vehicle-Id Component-Id Name Value Type\n" + body + "\n"
    return FirmwareExport(text, limits, reading)


def _largest_slope_mg_per_c(c_m_s2: np.ndarray, lo: float, hi: float,
                            t_ref: float) -> np.ndarray:
    """(3,) the file polynomial's largest |dp/dT| over TMIN..TMAX per axis, mg per °C
    (``c_m_s2``: (3, 4) in m/s² per °C^j about ``t_ref``)."""
    d = np.linspace(lo, hi, 201) - t_ref
    return np.array([np.max(np.abs(np.polynomial.polynomial.polyval(
        d, np.polynomial.polynomial.polyder(c_m_s2[i])))) if hi > lo else 0.0
        for i in range(3)]) / STANDARD_GRAVITY_M_S2 * 1e3


def ardupilot_temperature_filter(c_m_s2: np.ndarray, lo: float, hi: float,
                                 t_ref: float) -> str:
    """What ArduPilot's temperature filter costs (:mod:`calibration.firmware_flight`): its
    InvenSense backends hand ``correct_accel`` the reading through a 2-pole 1-Hz low-pass,
    which follows a changing reading :func:`~calibration.firmware_flight.ardupilot_filter_delay_s`
    behind, so the offset in use lags the file's offset at the current reading by up to the
    polynomial's largest |dp/dT| × that delay × dT/dt: per axis, mg per °C/min."""
    slope = _largest_slope_mg_per_c(c_m_s2, lo, hi, t_ref)
    delay_s = ardupilot_filter_delay_s()
    per_c_per_min = slope * delay_s / 60.0
    return ("ArduPilot's InvenSense IMU drivers (AP_InertialSensor_Invensense) low-pass filter "
            f"the temperature at {ARDUPILOT_TEMP_CUTOFF_HZ:g} Hz (2-pole) before applying "
            f"these, {delay_s:.3f} s behind a changing reading: the offset in use then lags "
            "the file's offset at the current reading by up to "
            + " / ".join(f"{v:.4f}" for v in per_c_per_min)
            + " mg per degC/min of the temperature's change (x / y / z); the ICM-42xxx "
            "(Invensensev3) and BMI088 drivers do not filter it")


def px4_update_gate(c_m_s2: np.ndarray, lo: float, hi: float, t_ref: float,
                    lsb_c: float | None = None) -> str:
    """What PX4's poll and update gate cost (:mod:`calibration.firmware_flight`): the offset
    in use is that of the reading at the last publishing poll, within
    :data:`~calibration.firmware_flight.PX4_UPDATE_GATE_C` (a strict ``> 1.0f`` test) of
    the reading at the last poll, which is up to one poll period
    (:data:`~calibration.firmware_flight.PX4_POLL_PERIOD_S`) old. So it differs from the
    file's offset at the current reading by up to the polynomial's largest |dp/dT| over
    TMIN..TMAX times (the gate + the reading's change since the last poll): for a channel
    quantised at ``lsb_c``, one level (its reading steps by one level between polls at a
    warm-up's rates; a dithered channel's flicker takes some samples one or two levels
    further, said in words: the record does not say whether the channel was dithered);
    for a fine one,
    what the temperature moves in a second, said in words.
    Per axis, mg. Not part of the figures at the firmware's reading, which evaluate the
    offset at every sample's reading."""
    slope = _largest_slope_mg_per_c(c_m_s2, lo, hi, t_ref)
    gate = PX4_UPDATE_GATE_C
    if lsb_c:
        span = gate + float(lsb_c)
        then = (f"up to {gate:g} degC from the reading at the last poll, plus this model's "
                f"{float(lsb_c):g} degC channel's one step since that poll: up to {span:g} degC "
                f"from the current reading, so up to "
                + _xyz([v * span for v in slope]) + " mg (x / y / z) for a channel "
                "that steps cleanly; NOT a bound for a dithered channel, whose flicker takes "
                "some samples one or two steps further (up to 1.7 x this on simulated "
                "dithered warm-ups)")
    else:
        then = (f"up to {gate:g} degC from the reading at the last poll, plus what the reading "
                f"moved since that poll (under {PX4_POLL_PERIOD_S:g} s): up to "
                + _xyz([v * gate for v in slope]) + f" mg (x / y / z) for the {gate:g} "
                f"degC gate, plus as much again per degC the reading moves in a second")
    return (f"PX4 computes the offset at the temperature reading of its {PX4_POLL_PERIOD_S:g}-s "
            f"poll and publishes it only when that reading has moved by more than {gate:g} "
            f"degC since the last one it published (TemperatureCompensation::"
            f"update_offsets_accel); a vehicle held at one temperature keeps that offset. The "
            f"offset in use is that of a reading {then}, beside the file's offset at the "
            f"current reading (its largest slope over TMIN..TMAX times that distance)")


def export_ardupilot(model: ThermalModel, *, instance: int = 1, source_name: str = "model",
                     temperature_reading: str = "filtered") -> FirmwareExport:
    """A Mission Planner / MAVProxy parameter file of ``INS_TCAL{instance}_*``;
    ``temperature_reading`` (:data:`TEMPERATURE_READINGS`): the reading the board's driver
    hands ``INS_TCAL``, which decides the polynomial written for a dithered channel."""
    if not 1 <= instance <= 3:
        raise ModelFileError(f"ArduPilot has INS_TCAL1..3; --instance {instance} is out of range")
    if temperature_reading not in TEMPERATURE_READINGS:
        raise ModelFileError(f"--temperature-reading: expected one of "
                             f"{', '.join(TEMPERATURE_READINGS)}, got {temperature_reading!r}")
    filtered = temperature_reading == "filtered"
    lo, hi = _check(model, "ArduPilot")
    a_lo, a_hi = ARDUPILOT_TEMP_LIMITS_C
    if lo < a_lo or hi > a_hi:
        raise ModelFileError(f"valid range {lo:.2f} .. {hi:.2f} degC is outside ArduPilot's "
                             f"INS_TCAL TMIN/TMAX range {a_lo:g} .. {a_hi:g} degC")
    # for the filtered drivers, the polynomial fitted at the filtered reading where the model
    # carries one (a dithered channel): the InvenSense drivers' 1-Hz filter
    # (calibration.firmware_flight); for the unfiltered ones, the per-sample polynomial
    c_m_s2 = bias_polynomials_m_s2(model, ARDUPILOT_TEMP_REFERENCE_C,
                                   file_bias_x_g(model, filtered=filtered))
    c = c_m_s2 * ARDUPILOT_SCALE_FACTOR
    limits = left_out(model, fold=filtered_fold_record(model) if filtered else None)
    filtered_record = firmware_reading_record(model, filtered=True)
    record = filtered_record if filtered else firmware_reading_record(model)
    reading = ardupilot_fitted_reading(filtered_record, temperature_reading) + \
        quantised_reading_lines(record) + rate_fold_warning(model)
    limits.append("the constant offset is not in INS_TCAL (no constant term): it is "
                  f"INS_ACC{'' if instance == 1 else instance}OFFS, measured by the ordinary "
                  "accelerometer calibration at INS_ACC"
                  f"{instance}_CALTEMP")
    p = f"INS_TCAL{instance}"
    rows: list[tuple[str, float]] = [(f"{p}_ENABLE", 1), (f"{p}_TMIN", lo), (f"{p}_TMAX", hi)]
    for j in (1, 2, 3):
        for i, axis in enumerate("XYZ"):
            rows.append((f"{p}_ACC{j}_{axis}", float(c[i, j])))
    head = _header(
        f"ArduPilot IMU temperature calibration from {source_name} (soakcal export)",
        ["v -= P(clamp(T) - 35) - P(clamp(T_cal) - 35), "
         "P(d) = (ACC1*d + ACC2*d^2 + ACC3*d^3) * 1e-6 m/s^2, per axis X, Y, Z",
         "35 degC is fixed in the firmware (TEMP_REFERENCE; there is no parameter for it)",
         "T is the IMU's own temperature; T_cal is INS_ACCn_CALTEMP; clamp to TMIN..TMAX",
         "the gyro coefficients (INS_TCALn_GYR*) are not touched",
         ardupilot_temperature_filter(c_m_s2, lo, hi, ARDUPILOT_TEMP_REFERENCE_C)],
        limits, reading)
    text = head + "\n".join(f"{n},{_num(v, 0)}" for n, v in rows) + "\n"
    return FirmwareExport(text, limits, reading)


def _header(title: str, formula: list[str], limits: list[str],
            reading: list[str] | None = None) -> str:
    reading = reading or []
    loud = [x for x in reading if x.startswith("WARNING")]
    lines = [title, *loud, *formula]
    quiet = [x for x in reading if not x.startswith("WARNING")]
    if quiet:
        lines.append("AT THE FIRMWARE'S OWN TEMPERATURE READING:")
        lines += [f"  - {x}" for x in quiet]
    if limits:
        lines.append("NOT EXPRESSED by this firmware's parameters:")
        lines += [f"  - {x}" for x in limits]
    return "".join(f"# {_ascii(x)}\n" for x in lines)


def _num(v: float, kind: int) -> str:
    if kind == PX4_PARAM_INT32:
        return str(int(v))
    if not math.isfinite(v):
        raise ModelFileError(f"coefficient {v!r} is not finite")
    return f"{v:.9g}"


def _ascii(text: str) -> str:
    return text.replace("°", "deg").replace("µ", "u").replace("−", "-")
