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


def reading_spread(read_c: np.ndarray, rebuilt_c: np.ndarray, lsb_c: float, level_c: float,
                   dither_lsb: float) -> tuple[np.ndarray, np.ndarray]:
    """(levels_c (L,), weights (n, L)): the share of each capture's samples the channel read
    at each of its levels, the readings the firmware evaluates its offset at one sample at a
    time (a capture mean of the reading is none of them). A dithered channel
    (``dither_lsb`` > 0, :mod:`calibration.temperature_dither`): the die at z (level units,
    the rebuilt temperature) is read at level j with probability Φ((z − j + ½)/σ) −
    Φ((z − j − ½)/σ), σ the channel's noise in LSB, as the rebuild's own model reads it. A
    channel that steps cleanly: a capture mean m between levels k and k + 1 is a share
    m − k of its samples at k + 1, the rest at k (one crossing inside a capture)."""
    from scipy.special import ndtr

    q = max(float(lsb_c), 1e-9)
    if dither_lsb > 0:
        z = (np.asarray(rebuilt_c, float) - level_c) / q
        j = np.arange(np.floor(np.min(z)) - 4, np.ceil(np.max(z)) + 5)
        upper = ndtr((z[:, None] - (j - 0.5)[None, :]) / dither_lsb)
        lower = ndtr((z[:, None] - (j + 0.5)[None, :]) / dither_lsb)
        return level_c + q * j, upper - lower
    m = (np.asarray(read_c, float) - level_c) / q
    k = np.floor(m + 1e-9)
    share_up = np.clip(m - k, 0.0, 1.0)
    j = np.arange(np.min(k), np.max(k) + 2)
    w = np.zeros((m.size, j.size))
    rows = np.arange(m.size)
    col = (k - j[0]).astype(int)
    w[rows, col] = 1.0 - share_up
    w[rows, col + 1] += share_up
    return level_c + q * j, w


def _firmware_design(model: ThermalModel, read_c: np.ndarray, lo: float, hi: float,
                     terms: int, spread: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """(n, terms): each capture's mean of the powers of x at the firmware's clamped reading:
    over its samples' readings (``spread``: :func:`reading_spread`), or at the capture
    mean of the reading itself (None: a firmware that low-pass filters its reading)."""
    if spread is None:
        return np.vander(model.x_of(np.clip(read_c, lo, hi)), terms, increasing=True)
    levels_c, weights = spread
    return weights @ np.vander(model.x_of(np.clip(levels_c, lo, hi)), terms, increasing=True)


def raw_reading_polynomial_x_g(model: ThermalModel, read_c: np.ndarray, rebuilt_c: np.ndarray,
                               lsb_c: float,
                               spread: tuple[np.ndarray, np.ndarray] | None = None,
                               rate_g: np.ndarray | None = None) -> np.ndarray:
    """(3, m+1) g in x: the offset polynomial in the firmware's own reading that is closest
    to the model on the fit log. Both firmwares subtract p(clamp(T_read)) (module
    docstring); the best any p can do at a reading is the log's mean bias there,
    E[b(T_rebuilt) | T_read], which differs from b(T_read) where the die's time inside a
    step is not centred on the step (a warm-up that settles at 35.3 °C reads 35 for its
    whole rest) and where a lagging channel reads behind the die. So p minimises
    Σ_i (b(T_rebuilt,i) − mean over capture i's samples of p(clamp(T_read)))² over the log's
    capture means: a least-squares polynomial of the firmware's degree (cubic), fewer
    terms when the reading takes fewer levels than that needs. The mean is over the
    readings the firmware evaluates p at, sample by sample (``spread``,
    :func:`reading_spread`; None: at the capture mean of the reading): a dithered
    channel's samples flicker over several levels, and p's clamp at TMIN/TMAX (where a
    warm-up rests) and its curvature make their mean p differ from p at their mean. Its
    target is the model's bias, not the readings: the fit smooths out the capture noise
    that PX4's and ArduPilot's scripts fit on the step values themselves. Same clamp and
    same readings as :func:`quantised_reading_error`.

    ``rate_g`` ((n, 3) g, each capture's rate term k(T)·dT/dt as ``compensate`` computes
    it): the target is then the model's whole offset b + k·dT/dt, and p is the
    least-squares polynomial in the reading of what the model says the offset is on the
    log (:func:`rate_fold_record`); the fit is linear in its target, so p is the
    polynomial of b plus that of the rate term alone."""
    lo, hi = model.valid_c or (float(np.min(rebuilt_c)), float(np.max(rebuilt_c)))
    read, rebuilt = np.asarray(read_c, float), np.asarray(rebuilt_c, float)
    ok = np.isfinite(read) & np.isfinite(rebuilt)
    if spread is not None:
        spread = (spread[0], spread[1][ok])
    target = model.params_vector_at(np.clip(rebuilt[ok], lo, hi), extrapolate=True)[:, sfem.BIAS]
    if rate_g is not None:
        target = target + np.asarray(rate_g, float)[ok]
    levels = np.unique(np.round(np.clip(read[ok], lo, hi) / max(float(lsb_c), 1e-9))).size
    degree = max(0, min(FIRMWARE_DEGREE, levels - 1))
    V = _firmware_design(model, read[ok], lo, hi, degree + 1, spread)
    coef = np.linalg.lstsq(V, target, rcond=None)[0].T  # (3, degree+1)
    return coef


def _spread_of(read: np.ndarray, rebuilt: np.ndarray, ok: np.ndarray, lsb_c: float,
               level_c: float | None, dither_lsb: float
               ) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`reading_spread` of every capture (a missing value read at the mean), or None
    without ``level_c`` (the firmware's reading taken at the capture mean)."""
    if level_c is None:
        return None
    return reading_spread(np.where(ok, read, np.nanmean(read[ok])),
                          np.where(ok, rebuilt, np.nanmean(rebuilt[ok])), lsb_c,
                          float(level_c), float(dither_lsb))


def _rms_of(d: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(d**2, axis=0)) if d.size else np.zeros(3)


def _reading_figures(model: ThermalModel, coef: np.ndarray, read_ok: np.ndarray,
                     whole_mg: np.ndarray, spread_ok: tuple[np.ndarray, np.ndarray] | None,
                     lsb_c: float, fit_heldout_mg: list[float] | None,
                     valid: tuple[float, float]) -> dict[str, object]:
    """The figures of the file polynomial ``coef`` ((3, m+1) g in x) at the firmware's
    reading against the model's whole offset ``whole_mg`` ((n, 3), mg) on the fit log's
    captures: RMS and peak per sample (``spread_ok``) and at the capture mean of the
    reading (``smoothed_rms_mg``), the offset's step per change of the reading
    (``tempco_lsb_mg``) and the RMS over the fit's own held-out RMS (``ratio_to_fit``)."""
    lo, hi = valid

    def exported_mg(t: np.ndarray, sp: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> np.ndarray:
        return _firmware_design(model, t, lo, hi, coef.shape[1], sp) @ coef.T * 1e3

    diff = exported_mg(read_ok, spread_ok) - whole_mg
    smoothed = exported_mg(read_ok) - whole_mg
    grid = np.linspace(lo, hi, 201)
    slope = (np.abs(np.gradient(exported_mg(grid), grid, axis=0)) if hi > lo
             else np.zeros((1, 3)))
    rms = _rms_of(diff)
    out: dict[str, object] = {
        "rms_mg": [float(v) for v in rms],
        "peak_mg": [float(v) for v in (np.max(np.abs(diff), axis=0) if diff.size
                                       else np.zeros(3))],
        "smoothed_rms_mg": [float(v) for v in _rms_of(smoothed)],
        "tempco_lsb_mg": [float(v) * float(lsb_c) for v in np.max(slope, axis=0)],
    }
    if fit_heldout_mg is not None:
        out["ratio_to_fit"] = float(np.max(rms / np.maximum(np.asarray(fit_heldout_mg), 1e-9)))
    return out


def quantised_reading_error(model: ThermalModel, read_c: np.ndarray, rebuilt_c: np.ndarray,
                            lsb_c: float, fit_heldout_mg: list[float] | None, *,
                            t_s: np.ndarray | None = None, level_c: float | None = None,
                            dither_lsb: float = 0.0) -> dict[str, object]:
    """What a firmware that reads the raw quantised channel makes of this model on its fit
    log, and the static polynomial in that reading (``raw_reading_bias_x_g``:
    :func:`raw_reading_polynomial_x_g` of the model's b alone). Both firmwares subtract
    p(clamp(T)) (module docstring) with T their own reading, while the model was fitted in
    the die temperature rebuilt from that channel (:mod:`calibration.temperature_dequantise`).
    The figures are of the file that polynomial makes; a model with a rate term is exported
    with the rate term folded in (:func:`rate_fold_record`), whose record carries the same
    figures for that file.

    Per axis, over the log's capture means: the RMS and largest difference (mg) between
    the offset the firmware subtracts and the model's whole offset, b(T_rebuilt) plus its
    rate term k(T)·dT/dt (``t_s`` given; the firmware's offset is a function of T only,
    so the rate term is part of what the file leaves undone on this log, said apart as
    ``rate_term_rms_mg``). The firmware's offset is the mean over each capture's samples
    of p(clamp(T_read)) at each sample's own reading (``level_c`` given:
    :func:`reading_spread`; PX4's ``calc_thermal_offsets_3D`` takes one reading, not an
    average), with ``smoothed_rms_mg`` the same figure with p at the capture mean of the
    reading (a firmware that low-pass filters its temperature, as ArduPilot's InvenSense
    drivers do at 1 Hz, evaluates p about there). Without ``level_c`` both are at the
    capture mean (a model file's record from before). Also the same RMS for the model's
    own b at the reading (``model_at_raw_rms_mg``: what exporting b(T) itself would cost);
    ``tempco_lsb_mg``, the largest |dp/dT| over the valid range times the LSB (the step the
    firmware's offset takes at each change of its reading); and the fit's own held-out RMS
    (mg) with the ratio of the stated RMS to it. The constant part (X0, INS_ACCOFFS)
    cancels in the difference, so the figure is the same for PX4 and ArduPilot."""
    lo, hi = model.valid_c or (float(np.min(rebuilt_c)), float(np.max(rebuilt_c)))
    read, rebuilt = np.asarray(read_c, float), np.asarray(rebuilt_c, float)
    ok = np.isfinite(read) & np.isfinite(rebuilt)
    spread = _spread_of(read, rebuilt, ok, lsb_c, level_c, dither_lsb)
    coef = raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c, spread)
    if spread is not None:
        spread = (spread[0], spread[1][ok])

    def bias_mg(t: np.ndarray) -> np.ndarray:
        P = model.params_vector_at(np.clip(t, lo, hi), extrapolate=True)
        return P[:, sfem.BIAS] * 1e3

    rate_mg = np.zeros((int(np.sum(ok)), 3))
    if t_s is not None and model.temperature_rate:
        from calibration.warmup import rate_offset_g

        rate_mg = rate_offset_g(model, np.asarray(t_s, float)[ok], rebuilt[ok]) * 1e3
    whole = bias_mg(rebuilt[ok]) + rate_mg  # what `compensate` subtracts
    figures = _reading_figures(model, coef, read[ok], whole, spread, lsb_c, fit_heldout_mg,
                               (lo, hi))
    model_diff = bias_mg(read[ok]) - whole
    out: dict[str, object] = {
        "lsb_c": float(lsb_c),
        "readings": int(np.sum(ok)),
        "per_sample": spread is not None,
        "rms_mg": figures["rms_mg"],
        "peak_mg": figures["peak_mg"],
        "smoothed_rms_mg": figures["smoothed_rms_mg"],
        "rate_term_rms_mg": [float(v) for v in _rms_of(rate_mg)],
        "model_at_raw_rms_mg": [float(v) for v in _rms_of(model_diff)],
        "tempco_lsb_mg": figures["tempco_lsb_mg"],
        "fit_heldout_mg": None if fit_heldout_mg is None else [float(v) for v in fit_heldout_mg],
        "raw_reading_bias_x_g": [[float(v) for v in axis] for axis in coef],
        "raw_reading_basis": ("p(T) = sum_j c[axis][j] * x**j in g, x = (clamp(T, valid) - "
                              "centre_c) / scale_c, T the channel's raw reading"),
    }
    if fit_heldout_mg is not None:
        out["ratio_to_fit"] = figures["ratio_to_fit"]
    return out


def _padded(coef: np.ndarray) -> np.ndarray:
    """(3, FIRMWARE_DEGREE + 1): ``coef`` with its missing higher powers as zeros."""
    out = np.zeros((3, FIRMWARE_DEGREE + 1))
    c = np.asarray(coef, float)
    out[:, : c.shape[1]] = c
    return out


def rate_fold_record(model: ThermalModel, t_s: np.ndarray, read_c: np.ndarray,
                     rebuilt_c: np.ndarray, fit_heldout_mg: list[float] | None, *,
                     lsb_c: float = 0.0, level_c: float | None = None,
                     dither_lsb: float = 0.0) -> dict[str, object] | None:
    """The rate term k(T)·dT/dt of a warm-up model folded into the firmware's polynomial,
    or None for a model without one.

    Neither firmware can apply a rate term (its offset is a function of its temperature
    reading only). The file's polynomial is then the least-squares polynomial in the
    firmware's reading of what the model says the offset is on the fit log, b(T) plus
    k(T)·dT/dt at each capture as ``compensate`` computes it
    (:func:`raw_reading_polynomial_x_g` with ``rate_g``), the reading being the raw channel
    (``lsb_c`` > 0: a model fitted in the temperature rebuilt from it, evaluated per sample
    with ``level_c``, :func:`reading_spread`) or the temperature itself (a fine channel:
    ``read_c`` = ``rebuilt_c``). During a warm-up dT/dt is largely a function of T, and a
    polynomial in T fitted jointly with a rate term leaves part of the T dependence in the
    term: dropping it undoes that part, folding its mean at each reading restores it. This
    is what PX4's and ArduPilot's own fits on a warm-up's samples do implicitly.

    The fit is linear in its target, so the file is the static polynomial (the model's
    b(T), or for a rebuilt channel its least-squares polynomial in the reading) plus
    ``folded_rate_x_g``, the least-squares polynomial of the rate term alone (g in x). At a
    constant temperature, where dT/dt = 0, the file differs from the static offset by that
    folded part: ``at_rest_rms_mg`` / ``at_rest_peak_mg`` over the valid range about its mean
    (``at_rest_mean_mg``: the constant part, which the firmware's ordinary calibration
    measures when X0 is 0 and INS_TCAL has none). On the fit log: ``rms_mg`` / ``peak_mg``,
    the folded file at the firmware's reading less the model's whole offset, and
    ``dropped_rms_mg`` / ``dropped_peak_mg``, the static file's (the rate term dropped);
    ``reading``, for a rebuilt channel, the figures of :func:`quantised_reading_error` for
    the folded file (the export states those)."""
    if not model.temperature_rate:
        return None
    from calibration.warmup import rate_offset_g

    read, rebuilt = np.asarray(read_c, float), np.asarray(rebuilt_c, float)
    ok = np.isfinite(read) & np.isfinite(rebuilt)
    lo, hi = model.valid_c or (float(np.min(rebuilt[ok])), float(np.max(rebuilt[ok])))
    rebuilt_channel = lsb_c > 0
    spread = _spread_of(read, rebuilt, ok, lsb_c, level_c, dither_lsb) if rebuilt_channel \
        else None
    rate_g = np.zeros((read.size, 3))
    rate_g[ok] = rate_offset_g(model, np.asarray(t_s, float)[ok], rebuilt[ok])
    static_ls = _padded(raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c, spread))
    whole_ls = _padded(raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c, spread,
                                                  rate_g=rate_g))
    folded = whole_ls - static_ls
    # the static file: the raw-reading polynomial for a rebuilt channel, b(T) itself else
    static = static_ls if rebuilt_channel else _padded(model.coeffs[sfem.BIAS])
    spread_ok = None if spread is None else (spread[0], spread[1][ok])
    whole_mg = (model.params_vector_at(np.clip(rebuilt[ok], lo, hi),
                                       extrapolate=True)[:, sfem.BIAS] + rate_g[ok]) * 1e3
    lsb = float(lsb_c)
    file_fig = _reading_figures(model, static + folded, read[ok], whole_mg, spread_ok, lsb,
                                fit_heldout_mg, (lo, hi))
    static_fig = _reading_figures(model, static, read[ok], whole_mg, spread_ok, lsb,
                                  fit_heldout_mg, (lo, hi))
    grid = np.linspace(lo, hi, 201)
    at_rest = np.vander(model.x_of(grid), FIRMWARE_DEGREE + 1, increasing=True) @ folded.T
    mean = at_rest.mean(axis=0)
    out: dict[str, object] = {
        "folded_rate_x_g": [[float(v) for v in axis] for axis in folded],
        "basis": ("p(T) = sum_j c[axis][j] * x**j in g, x = (clamp(T, valid) - centre_c) / "
                  "scale_c, T the firmware's reading; added to the static polynomial"),
        "reading": "raw" if rebuilt_channel else "temperature",
        "captures": int(np.sum(ok)),
        "rms_mg": file_fig["rms_mg"], "peak_mg": file_fig["peak_mg"],
        "dropped_rms_mg": static_fig["rms_mg"], "dropped_peak_mg": static_fig["peak_mg"],
        "rate_term_rms_mg": [float(v) for v in _rms_of(rate_g[ok] * 1e3)],
        "at_rest_rms_mg": [float(v) for v in _rms_of((at_rest - mean) * 1e3)],
        "at_rest_peak_mg": [float(v) for v in np.max(np.abs(at_rest - mean), axis=0) * 1e3],
        "at_rest_mean_mg": [float(v) for v in mean * 1e3],
        "fit_heldout_mg": None if fit_heldout_mg is None else [float(v) for v in fit_heldout_mg],
    }
    if fit_heldout_mg is not None:
        out["ratio_to_fit"] = file_fig["ratio_to_fit"]
    if rebuilt_channel:
        out["reading_figures"] = file_fig
    return out


def rate_fold_x_g(model: ThermalModel) -> np.ndarray | None:
    """The folded rate polynomial a warm-up model with a rate term carries
    (:func:`rate_fold_record`), or None (no rate term, or a model file from before)."""
    coef = (model.provenance.get("rate_fold") or {}).get("folded_rate_x_g")
    return None if coef is None else np.asarray(coef, float)


def file_bias_x_g(model: ThermalModel) -> np.ndarray | None:
    """The offset polynomial the export writes, in g in the model's x, or None for the
    model's own b(T): the static polynomial (:func:`raw_reading_bias_x_g` or b) plus the
    folded rate term (:func:`rate_fold_x_g`) where the model carries one."""
    static = raw_reading_bias_x_g(model)
    folded = rate_fold_x_g(model)
    if folded is None:
        return static
    return _padded(model.coeffs[sfem.BIAS] if static is None else static) + folded


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

    per_sample = bool(record.get("per_sample"))
    rate = record.get("rate_term_rms_mg")
    whose = ("the model's whole offset at the rebuilt temperature" if rate is not None
             else "the offset at the rebuilt temperature")
    how = ""
    if per_sample:
        how = (f", p evaluated at each sample's own reading as PX4 does (at the capture mean "
               f"of the reading instead, as a firmware that low-pass filters its reading "
               f"evaluates it: RMS {xyz(record['smoothed_rms_mg'])} mg)")
    dropped = ""
    folded = bool(record.get("rate_folded"))
    if folded:
        whose = "the model's whole offset (rate term included) at the rebuilt temperature"
        dropped = (f"; this includes what the polynomial cannot follow of the model's rate "
                   f"term k(T)*dT/dt, whose mean at each reading it folds in (the term alone: "
                   f"RMS {xyz(rate)} mg on the fit log; see FOLDED below)")
    elif rate is not None and max(rate) > 0:  # type: ignore[arg-type]
        dropped = (f"; this includes the model's rate term k(T)*dT/dt, which the firmware "
                   f"cannot apply (alone RMS {xyz(rate)} mg on the fit log)")
    of = ("the model's whole offset b + k*dT/dt" if folded else "the model's offset")
    if in_reading:
        main = (f"the model was fitted in the die temperature rebuilt from a {q:g} degC "
                f"channel, and the firmware evaluates its offset at its own {q:g} degC "
                f"reading: this file's polynomial is in that reading, the least-squares fit "
                f"over the fit log's {record['readings']} capture means of {of} "
                f"at the rebuilt temperature against the reading clamped to TMIN..TMAX (the "
                f"model's own b(T) evaluated at the reading instead: RMS "
                f"{xyz(record['model_at_raw_rms_mg'])} mg); on the fit log it differs from "
                f"{whose} by RMS {xyz(rms)} mg, peak {xyz(peak)} mg (x / y / z){how}"
                f"{dropped}; the offset steps by up to {xyz(step)} mg at each change of the "
                f"reading (tempco x LSB)")
        why = "and this file's polynomial is already the least-squares one in it"
    else:
        main = (f"the model was fitted in the die temperature rebuilt from a {q:g} degC "
                f"channel, but the firmware evaluates it at its own {q:g} degC reading: on "
                f"the fit log ({record['readings']} capture means) that differs from "
                f"{whose} by RMS {xyz(rms)} mg, peak {xyz(peak)} "
                f"mg (x / y / z){how}{dropped}; the offset steps by up to {xyz(step)} mg at "
                f"each change of the reading (tempco x LSB)")
        why = ("a fit on the step values, as PX4's and ArduPilot's scripts make, does about "
               "as well")
    if fit is None:
        return [main]
    ratio = float(record.get("ratio_to_fit", 0.0))  # type: ignore[arg-type]
    versus = (f"the fit's own held-out RMS is {xyz(fit)} mg (the file's error on such data "
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
        fold = model.provenance.get("rate_fold")
        out.append(rate_term_folded(fold) if fold and fold.get("folded_rate_x_g") is not None
                   else rate_term_dropped(model))
    held = [n for n, ok in zip(sfem.PARAM_NAMES[:3], model.identifiable[:3], strict=True)
            if not ok]
    reasons = getattr(model, "held", {}) or {}
    for name in held:
        # the file writes 0 for that axis' polynomial: the firmware leaves it uncompensated
        why = reasons.get(name, "not identifiable from these data")
        out.append(f"{name} not fitted, its polynomial written as 0 (that axis left "
                   f"uncompensated): {why}")
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
    """What folding a warm-up's rate term into the polynomial does (:func:`rate_fold_record`):
    right on average for warm-ups like the fit log, off at rest by the folded part."""

    def xyz(v: object) -> str:
        return " / ".join(f"{x:.3f}" for x in v)  # type: ignore[attr-defined]

    where = ("at the firmware's raw reading" if fold.get("reading") == "raw"
             else "in T")
    return (f"FOLDED: the warm-up's rate term k(T)*dT/dt (the firmware's offset is a function "
            f"of T only): this file's polynomial is the least-squares fit {where} of the "
            f"model's whole offset b(T) + k(T)*dT/dt over the fit log's {fold['captures']} "
            f"capture means, as PX4's and ArduPilot's own fits on a warm-up's samples fold the "
            f"log's mean rate effect into T; on the fit log it differs from that whole offset "
            f"by RMS {xyz(fold['rms_mg'])} mg, peak {xyz(fold['peak_mg'])} mg (x / y / z; "
            f"with the rate term dropped: RMS {xyz(fold['dropped_rms_mg'])} mg). It is right "
            f"on average for warm-ups like the fit log (the same rates at the same "
            f"temperatures); at a constant temperature (dT/dt = 0) it differs from the "
            f"model's static offset by the folded part: RMS {xyz(fold['at_rest_rms_mg'])} mg, "
            f"peak {xyz(fold['at_rest_peak_mg'])} mg over TMIN..TMAX about its mean (the mean, "
            f"{xyz(fold['at_rest_mean_mg'])} mg, is a constant: the ordinary accelerometer "
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

    def xyz(v: object) -> str:
        return " / ".join(f"{x:.3f}" for x in v)  # type: ignore[attr-defined]

    return [f"WARNING: the firmware cannot apply this warm-up's rate term k(T)*dT/dt: on the "
            f"fit log the file (the term's mean at each temperature folded in) differs from "
            f"the model's whole offset by up to {float(ratio):.1f} x the fit's own held-out "
            f"RMS {xyz(fold['fit_heldout_mg'])} mg: RMS {xyz(fold['rms_mg'])} mg (x / y / z; "
            f"see FOLDED below). No parameter file removes it (the firmware's offset is a "
            f"function of T only); `soakcal compensate` applies the rate term"]


def firmware_reading_record(model: ThermalModel) -> dict[str, object] | None:
    """The record :func:`quantised_reading_lines` states: the model's
    ``quantised_temperature`` record, with the figures of the file that folds the rate term
    (:func:`rate_fold_record`) where the model carries that fold."""
    record = model.provenance.get("quantised_temperature")
    fold = model.provenance.get("rate_fold") or {}
    figures = fold.get("reading_figures")
    if not record or not figures or fold.get("folded_rate_x_g") is None:
        return record
    return {**record, **figures, "rate_folded": True}


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
         px4_update_gate(c, lo, hi, t_ref), x0_note],
        limits, reading)
    body = "\n".join(f"1\t1\t{n}\t{_num(v, t)}\t{t}" for n, v, t in rows)
    text = head + "# Vehicle-Id Component-Id Name Value Type\n" + body + "\n"
    return FirmwareExport(text, limits, reading)


# PX4 publishes a new thermal offset only when the temperature it polls (once a second) has
# moved by more than this since the offset it last published (TemperatureCompensation::
# update_offsets_accel, TemperatureCompensationModule::Run at 1 Hz).
PX4_UPDATE_GATE_C = 1.0


def px4_update_gate(c_m_s2: np.ndarray, lo: float, hi: float, t_ref: float) -> str:
    """What PX4's update gate costs: the offset in use may be that of a reading up to
    :data:`PX4_UPDATE_GATE_C` away from the current one (a ``> 1.0`` test: with a 1 °C
    channel, one level either side), so up to the polynomial's largest |dp/dT| over
    TMIN..TMAX times that, per axis (mg). Not part of the figures at the firmware's reading,
    which evaluate the offset at every sample's reading."""
    d = np.linspace(lo, hi, 201) - t_ref
    slope = np.array([np.max(np.abs(np.polynomial.polynomial.polyval(
        d, np.polynomial.polynomial.polyder(c_m_s2[i])))) if hi > lo else 0.0
        for i in range(3)])
    cost_mg = slope * PX4_UPDATE_GATE_C / STANDARD_GRAVITY_M_S2 * 1e3
    return (f"PX4 publishes a new offset only when its temperature reading (polled once a "
            f"second) has moved by more than {PX4_UPDATE_GATE_C:g} degC since the last one "
            f"it published: the offset in use may be that of a reading up to "
            f"{PX4_UPDATE_GATE_C:g} degC away, up to "
            + " / ".join(f"{v:.3f}" for v in cost_mg) + " mg (x / y / z)")


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
                              file_bias_x_g(model)) * ARDUPILOT_SCALE_FACTOR
    limits = left_out(model)
    reading = quantised_reading_lines(firmware_reading_record(model)) + \
        rate_fold_warning(model)
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
