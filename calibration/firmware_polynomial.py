"""The offset polynomial the autopilots apply, fitted on the calibration log, and what it
costs (the file text: :mod:`calibration.export_firmware`).

Both firmwares subtract a cubic p(clamp(T)) in their own temperature reading T
(export_firmware's module docstring). Where soakcal's model is not such a polynomial, the
file carries the least-squares polynomial in the firmware's reading of what the model says
the offset is on the fit log: for a model fitted in the temperature rebuilt from a coarse
channel, against the raw reading per sample (:func:`raw_reading_polynomial_x_g`,
:func:`quantised_reading_error`); for a warm-up model with a rate term k(T)·dT/dt, with the
term's average at each reading folded in (:func:`rate_fold_record`). ``calibrate`` fits
both on the log and stores them in the model's provenance; the export reads them back
(:func:`file_bias_x_g`).
"""

from __future__ import annotations

import numpy as np

from calibration import sfem
from calibration.thermal import ThermalModel

FIRMWARE_DEGREE = 3  # both firmwares: cubic offset polynomial


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
                               rate_g: np.ndarray | None = None, *,
                               with_bias: bool = True) -> np.ndarray:
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
    polynomial of b plus that of the rate term alone (``with_bias=False``: that alone)."""
    lo, hi = model.valid_c or (float(np.min(rebuilt_c)), float(np.max(rebuilt_c)))
    read, rebuilt = np.asarray(read_c, float), np.asarray(rebuilt_c, float)
    ok = np.isfinite(read) & np.isfinite(rebuilt)
    if spread is not None:
        spread = (spread[0], spread[1][ok])
    target = (model.params_vector_at(np.clip(rebuilt[ok], lo, hi), extrapolate=True)[:, sfem.BIAS]
              if with_bias else np.zeros((int(np.sum(ok)), 3)))
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
    reading (``smoothed_rms_mg``, ``smoothed_peak_mg``), the offset's step per change of the reading
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
        "smoothed_peak_mg": [float(v) for v in (np.max(np.abs(smoothed), axis=0)
                                                if smoothed.size else np.zeros(3))],
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
    if spread is not None and dither_lsb > 0:
        # a firmware that low-pass filters a flickering (dithered) reading (ArduPilot's
        # InvenSense drivers, 1 Hz) evaluates p about the capture mean of the reading, not
        # at each sample's level: the polynomial fitted there (a channel that steps cleanly
        # holds each level for longer than the filter averages: the per-sample one is it)
        filtered = raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c, None)
        out["filtered_reading_bias_x_g"] = [[float(v) for v in axis] for axis in filtered]
        out["filtered_reading_figures"] = _reading_figures(
            model, filtered, read[ok], whole, spread, lsb_c, fit_heldout_mg, (lo, hi))
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
                     dither_lsb: float = 0.0,
                     reading_record: dict[str, object] | None = None
                     ) -> dict[str, object] | None:
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
    the folded file (the export states those). ``reading_record``: the output of
    :func:`quantised_reading_error` on the same log, whose static polynomials are used
    instead of fitting them again."""
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
    # the fit is linear in its target: the folded part is the rate term's own polynomial
    folded = _padded(raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c, spread,
                                                rate_g=rate_g, with_bias=False))
    # the static file: the raw-reading polynomial for a rebuilt channel, b(T) itself else
    static = _padded(_static_reading_x_g(model, read, rebuilt, lsb_c, spread, reading_record)
                     if rebuilt_channel else model.coeffs[sfem.BIAS])
    spread_ok = None if spread is None else (spread[0], spread[1][ok])
    whole_mg = (model.params_vector_at(np.clip(rebuilt[ok], lo, hi),
                                       extrapolate=True)[:, sfem.BIAS] + rate_g[ok]) * 1e3
    lsb = float(lsb_c)
    file_fig = _reading_figures(model, static + folded, read[ok], whole_mg, spread_ok, lsb,
                                fit_heldout_mg, (lo, hi))
    static_fig = _reading_figures(model, static, read[ok], whole_mg, spread_ok, lsb,
                                  fit_heldout_mg, (lo, hi))
    out: dict[str, object] = {
        "folded_rate_x_g": [[float(v) for v in axis] for axis in folded],
        "basis": ("p(T) = sum_j c[axis][j] * x**j in g, x = (clamp(T, valid) - centre_c) / "
                  "scale_c, T the firmware's reading; added to the static polynomial"),
        "reading": "raw" if rebuilt_channel else "temperature",
        "captures": int(np.sum(ok)),
        "rms_mg": file_fig["rms_mg"], "peak_mg": file_fig["peak_mg"],
        "dropped_rms_mg": static_fig["rms_mg"], "dropped_peak_mg": static_fig["peak_mg"],
        "rate_term_rms_mg": [float(v) for v in _rms_of(rate_g[ok] * 1e3)],
        **at_rest_figures(model, folded),
        "fit_heldout_mg": None if fit_heldout_mg is None else [float(v) for v in fit_heldout_mg],
    }
    if fit_heldout_mg is not None:
        out["ratio_to_fit"] = file_fig["ratio_to_fit"]
    if rebuilt_channel:
        out["reading_figures"] = file_fig
    if spread is not None and dither_lsb > 0:
        # the same fold for a firmware that low-pass filters its reading (at the capture
        # mean of the reading: quantised_reading_error's filtered polynomial)
        static_f = _padded(_static_reading_x_g(model, read, rebuilt, lsb_c, None,
                                               reading_record))
        folded_f = _padded(raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c, None,
                                                      rate_g=rate_g, with_bias=False))
        out["filtered_folded_rate_x_g"] = [[float(v) for v in axis] for axis in folded_f]
        out["filtered_reading_figures"] = _reading_figures(
            model, static_f + folded_f, read[ok], whole_mg, spread_ok, lsb, fit_heldout_mg,
            (lo, hi))
    return out


def _static_reading_x_g(model: ThermalModel, read: np.ndarray, rebuilt: np.ndarray,
                        lsb_c: float, spread: tuple[np.ndarray, np.ndarray] | None,
                        reading_record: dict[str, object] | None) -> np.ndarray:
    """The static raw-reading polynomial, per sample with ``spread``, else at the capture
    mean of the reading: the one :func:`quantised_reading_error` fitted on the same log
    (``reading_record``, its output), or fitted here without it."""
    key = "raw_reading_bias_x_g" if spread is not None else "filtered_reading_bias_x_g"
    carried = (reading_record or {}).get(key)
    if carried is not None:
        return np.asarray(carried, float)
    return raw_reading_polynomial_x_g(model, read, rebuilt, lsb_c, spread)


def at_rest_figures(model: ThermalModel, folded_x_g: np.ndarray) -> dict[str, list[float]]:
    """What a folded rate polynomial ``folded_x_g`` ((3, m+1) g in x) adds to the file at a
    constant temperature (dT/dt = 0, no rate effect to fold): its RMS and peak over the
    valid range (201 points) about its mean (``at_rest_rms_mg``, ``at_rest_peak_mg``) and
    the mean (``at_rest_mean_mg``, a constant the firmware's ordinary calibration
    measures), mg per axis."""
    lo, hi = model.valid_c or (model.t_centre_c, model.t_centre_c)
    folded = np.asarray(folded_x_g, float)
    grid = np.linspace(lo, hi, 201)
    at_rest = np.vander(model.x_of(grid), folded.shape[1], increasing=True) @ folded.T
    mean = at_rest.mean(axis=0)
    return {"at_rest_rms_mg": [float(v) for v in _rms_of((at_rest - mean) * 1e3)],
            "at_rest_peak_mg": [float(v) for v in np.max(np.abs(at_rest - mean), axis=0) * 1e3],
            "at_rest_mean_mg": [float(v) for v in mean * 1e3]}


def rate_fold_x_g(model: ThermalModel, filtered: bool = False) -> np.ndarray | None:
    """The folded rate polynomial a warm-up model with a rate term carries
    (:func:`rate_fold_record`), or None (no rate term, or a model file from before);
    ``filtered``: the one fitted at the filtered reading where the model carries it."""
    fold = model.provenance.get("rate_fold") or {}
    coef = (fold.get("filtered_folded_rate_x_g") if filtered else None) or \
        fold.get("folded_rate_x_g")
    return None if coef is None else np.asarray(coef, float)


def file_bias_x_g(model: ThermalModel, filtered: bool = False) -> np.ndarray | None:
    """The offset polynomial the export writes, in g in the model's x, or None for the
    model's own b(T): the static polynomial (:func:`raw_reading_bias_x_g` or b) plus the
    folded rate term (:func:`rate_fold_x_g`) where the model carries one. ``filtered``: the
    file for a firmware that low-pass filters its reading (ArduPilot's InvenSense drivers,
    :mod:`calibration.firmware_flight`), fitted at the capture mean of the reading of a
    dithered channel instead of at each sample's reading (the same polynomial where the
    model carries no such fit)."""
    static = raw_reading_bias_x_g(model, filtered)
    folded = rate_fold_x_g(model, filtered)
    if folded is None:
        return static
    return _padded(model.coeffs[sfem.BIAS] if static is None else static) + folded


def raw_reading_bias_x_g(model: ThermalModel, filtered: bool = False) -> np.ndarray | None:
    """The raw-reading polynomial a model fitted in a rebuilt temperature carries
    (:func:`quantised_reading_error`), or None: then the export writes the model's b(T)
    (a model read by a fine channel, or a model file from before the polynomial);
    ``filtered``: the one fitted at the capture mean of the reading where it carries it."""
    record = model.provenance.get("quantised_temperature") or {}
    coef = (record.get("filtered_reading_bias_x_g") if filtered else None) or \
        record.get("raw_reading_bias_x_g")
    return None if coef is None else np.asarray(coef, float)
