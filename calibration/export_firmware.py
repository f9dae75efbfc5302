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
from calibration.thermal import ThermalModel

STANDARD_GRAVITY_M_S2 = 9.80665  # PX4 CONSTANTS_ONE_G and ArduPilot GRAVITY_MSS
FIRMWARE_DEGREE = 3  # both firmwares: cubic offset polynomial
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


def bias_polynomials_m_s2(model: ThermalModel, t_ref_c: float,
                          bias_x_g: np.ndarray | None = None) -> np.ndarray:
    """(3, 4): bias b_i(T) in m/s² as Σ_j c_ij (T − t_ref)^j: an exact re-expansion of the
    model's Eq. 8 bias, or of ``bias_x_g`` ((3, m+1), g, in the model's x = (T − centre) /
    scale: the raw-reading polynomial of :func:`raw_reading_polynomial_x_g`)."""
    shift = Polynomial([(t_ref_c - model.t_centre_c) / model.t_scale_c, 1.0 / model.t_scale_c])
    coeffs = model.coeffs[sfem.BIAS] if bias_x_g is None else np.asarray(bias_x_g, float)
    out = np.zeros((3, FIRMWARE_DEGREE + 1))
    for i in range(3):
        poly = Polynomial(coeffs[i])(shift)
        c = poly.coef * STANDARD_GRAVITY_M_S2
        out[i, : c.size] = c
    return out


def raw_reading_polynomial_x_g(model: ThermalModel, read_c: np.ndarray, rebuilt_c: np.ndarray,
                               lsb_c: float) -> np.ndarray:
    """(3, m+1) g in x: the offset polynomial in the firmware's own reading that is closest
    to the model on the fit log. Both firmwares subtract p(clamp(T_read)) (module
    docstring); the best any p can do at a reading is the log's mean bias there,
    E[b(T_rebuilt) | T_read], which differs from b(T_read) where the die's time inside a
    step is not centred on the step (a warm-up that settles at 35.3 °C reads 35 for its
    whole rest) and where a lagging channel reads behind the die. So p minimises
    Σ_i (b(T_rebuilt,i) − p(clamp(T_read,i)))² over the log's capture means: a least-squares
    polynomial of the firmware's degree (cubic), fewer terms when the reading takes fewer
    levels than that needs. Its target is the model's bias, not the readings: the fit
    smooths out the capture noise that PX4's and ArduPilot's scripts fit on the step
    values themselves. Same clamp and same capture-mean reading as
    :func:`quantised_reading_error`."""
    lo, hi = model.valid_c or (float(np.min(rebuilt_c)), float(np.max(rebuilt_c)))
    read, rebuilt = np.asarray(read_c, float), np.asarray(rebuilt_c, float)
    ok = np.isfinite(read) & np.isfinite(rebuilt)
    x = model.x_of(np.clip(read[ok], lo, hi))
    target = model.params_vector_at(np.clip(rebuilt[ok], lo, hi), extrapolate=True)[:, sfem.BIAS]
    levels = np.unique(np.round(np.clip(read[ok], lo, hi) / max(float(lsb_c), 1e-9))).size
    degree = max(0, min(FIRMWARE_DEGREE, levels - 1))
    V = np.vander(x, degree + 1, increasing=True)
    coef = np.linalg.lstsq(V, target, rcond=None)[0].T  # (3, degree+1)
    return coef


def quantised_reading_error(model: ThermalModel, read_c: np.ndarray, rebuilt_c: np.ndarray,
                            lsb_c: float, fit_heldout_mg: list[float] | None
                            ) -> dict[str, object]:
    """What a firmware that reads the raw quantised channel makes of this model on its fit
    log, and the polynomial the export writes for it (``raw_reading_bias_x_g``:
    :func:`raw_reading_polynomial_x_g`). Both firmwares subtract p(clamp(T)) (module
    docstring) with T their own reading, while the model was fitted in the die
    temperature rebuilt from that channel (:mod:`calibration.temperature_dequantise`).
    Per axis, over the log's capture means: the RMS and largest |p(T_read) − b(T_rebuilt)|
    (mg) of the exported p, each clamped to the valid range as the firmwares clamp to
    TMIN/TMAX, and the same RMS for the model's own b at the reading
    (``model_at_raw_rms_mg``: what exporting b(T) itself would cost); ``tempco_lsb_mg``,
    the largest |dp/dT| over the valid range times the LSB (the step the firmware's offset
    takes at each change of its reading); and the fit's own held-out RMS (mg) with the
    ratio of the exported p's RMS to it. The constant part (X0, INS_ACCOFFS) cancels in
    the difference, so the figure is the same for PX4 and ArduPilot. A capture's raw mean
    stands for its samples' readings: p is smooth, so the mean of p over a capture's
    samples and p at their mean differ by second-order terms only."""
    lo, hi = model.valid_c or (float(np.min(rebuilt_c)), float(np.max(rebuilt_c)))
    read, rebuilt = np.asarray(read_c, float), np.asarray(rebuilt_c, float)
    ok = np.isfinite(read) & np.isfinite(rebuilt)
    coef = raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c)

    def bias_mg(t: np.ndarray) -> np.ndarray:
        P = model.params_vector_at(np.clip(t, lo, hi), extrapolate=True)
        return P[:, sfem.BIAS] * 1e3

    def exported_mg(t: np.ndarray) -> np.ndarray:
        V = np.vander(model.x_of(np.clip(t, lo, hi)), coef.shape[1], increasing=True)
        return V @ coef.T * 1e3

    at_rebuilt = bias_mg(rebuilt[ok])
    diff = exported_mg(read[ok]) - at_rebuilt
    model_diff = bias_mg(read[ok]) - at_rebuilt
    grid = np.linspace(lo, hi, 201)
    slope = (np.abs(np.gradient(exported_mg(grid), grid, axis=0)) if hi > lo
             else np.zeros((1, 3)))

    def rms_of(d: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean(d**2, axis=0)) if d.size else np.zeros(3)

    rms = rms_of(diff)
    out: dict[str, object] = {
        "lsb_c": float(lsb_c),
        "readings": int(np.sum(ok)),
        "rms_mg": [float(v) for v in rms],
        "peak_mg": [float(v) for v in (np.max(np.abs(diff), axis=0) if diff.size
                                       else np.zeros(3))],
        "model_at_raw_rms_mg": [float(v) for v in rms_of(model_diff)],
        "tempco_lsb_mg": [float(v) * float(lsb_c) for v in np.max(slope, axis=0)],
        "fit_heldout_mg": None if fit_heldout_mg is None else [float(v) for v in fit_heldout_mg],
        "raw_reading_bias_x_g": [[float(v) for v in axis] for axis in coef],
        "raw_reading_basis": ("p(T) = sum_j c[axis][j] * x**j in g, x = (clamp(T, valid) - "
                              "centre_c) / scale_c, T the channel's raw reading"),
    }
    if fit_heldout_mg is not None:
        out["ratio_to_fit"] = float(np.max(rms / np.maximum(np.asarray(fit_heldout_mg), 1e-9)))
    return out


def raw_reading_bias_x_g(model: ThermalModel) -> np.ndarray | None:
    """The raw-reading polynomial a model fitted in a rebuilt temperature carries
    (:func:`quantised_reading_error`), or None: then the export writes the model's b(T)
    (a model read by a fine channel, or a model file from before the polynomial)."""
    record = model.provenance.get("quantised_temperature") or {}
    coef = record.get("raw_reading_bias_x_g")
    return None if coef is None else np.asarray(coef, float)


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

    def xyz(v: object) -> str:
        return " / ".join(f"{x:.3f}" for x in v)  # type: ignore[attr-defined]

    if in_reading:
        main = (f"the model was fitted in the die temperature rebuilt from a {q:g} degC "
                f"channel, and the firmware evaluates its offset at its own {q:g} degC "
                f"reading: this file's polynomial is in that reading, the least-squares fit "
                f"over the fit log's {record['readings']} capture means of the model's offset "
                f"at the rebuilt temperature against the reading clamped to TMIN..TMAX (the "
                f"model's own b(T) evaluated at the reading instead: RMS "
                f"{xyz(record['model_at_raw_rms_mg'])} mg); on the fit log it differs from "
                f"the offset at the rebuilt temperature by RMS {xyz(rms)} mg, peak "
                f"{xyz(peak)} mg (x / y / z); the offset steps by up to {xyz(step)} mg at "
                f"each change of the reading (tempco x LSB)")
        why = "and this file's polynomial is already the least-squares one in it"
    else:
        main = (f"the model was fitted in the die temperature rebuilt from a {q:g} degC "
                f"channel, but the firmware evaluates it at its own {q:g} degC reading: on "
                f"the fit log ({record['readings']} capture means) that differs from the "
                f"offset at the rebuilt temperature by RMS {xyz(rms)} mg, peak {xyz(peak)} "
                f"mg (x / y / z); the offset steps by up to {xyz(step)} mg at each change "
                f"of the reading (tempco x LSB)")
        why = ("a fit on the step values, as PX4's and ArduPilot's scripts make, does about "
               "as well")
    if fit is None:
        return [main]
    ratio = float(record.get("ratio_to_fit", 0.0))  # type: ignore[arg-type]
    versus = f"the fit's own held-out RMS is {xyz(fit)} mg"
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


def left_out(model: ThermalModel, n_temps: int = 41) -> list[str]:
    """What an offset-only export cannot express, each with the error it costs (mg at 1 g)."""
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
        out.append(rate_term_dropped(model))
    held = [n for n, ok in zip(sfem.PARAM_NAMES[:3], model.identifiable[:3], strict=True)
            if not ok]
    if held:
        out.append(f"{', '.join(held)} held, not fitted: that axis' offset is not a calibration")
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


def export_px4(model: ThermalModel, *, instance: int = 0, device_id: int = 0,
               source_name: str = "model") -> FirmwareExport:
    """A QGroundControl parameter file of ``TC_A{instance}_*`` (see module docstring)."""
    if not 0 <= instance <= 3:
        raise ModelFileError(f"PX4 has TC_A0..TC_A3; --instance {instance} is out of range")
    lo, hi = _check(model, "PX4")
    t_ref = 0.5 * (lo + hi)  # as PX4's process_sensor_caldata.py: mid-range reference
    c = bias_polynomials_m_s2(model, t_ref, raw_reading_bias_x_g(model))
    limits = left_out(model)
    reading = quantised_reading_lines(model.provenance.get("quantised_temperature"))
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
         x0_note],
        limits, reading)
    body = "\n".join(f"1\t1\t{n}\t{_num(v, t)}\t{t}" for n, v, t in rows)
    text = head + "# Vehicle-Id Component-Id Name Value Type\n" + body + "\n"
    return FirmwareExport(text, limits, reading)


def export_ardupilot(model: ThermalModel, *, instance: int = 1,
                     source_name: str = "model") -> FirmwareExport:
    """A Mission Planner / MAVProxy parameter file of ``INS_TCAL{instance}_*``."""
    if not 1 <= instance <= 3:
        raise ModelFileError(f"ArduPilot has INS_TCAL1..3; --instance {instance} is out of range")
    lo, hi = _check(model, "ArduPilot")
    a_lo, a_hi = ARDUPILOT_TEMP_LIMITS_C
    if lo < a_lo or hi > a_hi:
        raise ModelFileError(f"valid range {lo:.2f} .. {hi:.2f} degC is outside ArduPilot's "
                             f"INS_TCAL TMIN/TMAX range {a_lo:g} .. {a_hi:g} degC")
    c = bias_polynomials_m_s2(model, ARDUPILOT_TEMP_REFERENCE_C,
                              raw_reading_bias_x_g(model)) * ARDUPILOT_SCALE_FACTOR
    limits = left_out(model)
    reading = quantised_reading_lines(model.provenance.get("quantised_temperature"))
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
         "the gyro coefficients (INS_TCALn_GYR*) are not touched"],
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
