"""Import static multi-position recordings from other labs into recording format v1.

Four source formats (public recordings from other labs, docs/realdata.md), each read
into a :class:`RawImport` (time, acceleration in g, and what the file says about its
initial rest), then cut into static intervals and averaged into one v1 row per interval:

* ``openaxes`` -- OpenAXES IMU logger, semicolon CSV, ADXL355 (or BMI160) in m/s².
* ``imu_tk``   -- imu_tk / Tedaldi test data: ASCII ``t ax ay az`` in raw ADC counts.
* ``ferraris`` -- imucal Ferraris session: CSV (m/s²) + session-list JSON, or the
  annotated CSV (``part`` column, raw counts).
* ``mpu6050``  -- tomisuarez2/ImuCalibration: 4-line ``key,value`` preamble, int16
  counts at ±2 g (16384 LSB/g).

Logs that carry the sensor's own temperature (:mod:`calibration.importers_logs`:
``ulog`` PX4, ``dataflash`` ArduPilot; :mod:`calibration.importers_table`: ``csv``; and
``openaxes`` when its ``TEMP`` output was logged) keep it as ``sensor_c`` (recording
format: the sensor's own temperature reading). A source without one is written with an
empty ``chamber_c`` column: one step at an unknown temperature. We never invent a
temperature, and every reader says in its notes what it could not read.

Static-interval rule (:func:`detect_static_intervals`, after Tedaldi et al. ICRA 2014
and imu_tk): for every sample, the variance of each axis over a centred window of
``window_s`` seconds; the sample is *static* when the magnitude of that variance
vector, ‖(σx², σy², σz²)‖, is below ``threshold`` × the same magnitude measured
over the initial rest (the first ``init_rest_s`` seconds; without one, the quietest
10 % of the log's windows). Runs of static samples lasting at least ``min_duration_s``
are intervals; ``trim_s`` is then cut from both ends of each, because the hand
placement still rings and settles there (the moving window only notices motion half
a window late). A reference noisier than a still accelerometer ever is
(:data:`STILL_NOISE_CEILING_G`, judged on :data:`STILL_LOWPASS_S` means, so that a
noisy part's white noise is not taken for motion) is not a rest: a log that moves or
vibrates from its first sample (a flight) would be "static" against its own quietest
part, so such a log is static only where its scatter is under that ceiling
(:func:`still_reference`).
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from calibration.errors import RecordingError
from calibration.gate import STANDARD_GRAVITY_M_S2, gravity_problem
from calibration.importers_plain import is_plain, parse_plain_rows
from calibration.placement import HAND_HELD_TOL_DEG, REF_TOL_COLUMN
from calibration.recording import Recording

FORMATS: tuple[str, ...] = (
    "openaxes", "imu_tk", "ferraris", "mpu6050", "ulog", "dataflash", "csv")
# Formats that are time series of one (or a few) orientations with a temperature (a
# warm-up): their default output is every sample, not static-interval means.
LOG_FORMATS: tuple[str, ...] = ("ulog", "dataflash", "csv")
# A die temperature outside this span is a unit or scale mistake, not a reading
# (MEMS parts are specified over -40..+125 °C; margin for chamber overshoot).
PLAUSIBLE_DIE_C: tuple[float, float] = (-60.0, 150.0)
# A die sensor read in every sample of a powered board for this long moves by at least
# its last digit (self-heating after power-up, the room, the readout's own noise): a
# value bit-identical over a longer log is a placeholder, not a reading.
CONSTANT_TEMP_LONG_S = 600.0
# What an empty temperature means downstream (docs/importers.md, "Temperatures that are
# not readings"): said once in every note that empties a channel.
NO_TEMP_CONSEQUENCE = ("calibrate sees one step at an unknown temperature; a warm-up "
                       "calibration needs a measured temperature")
NO_TEMP_IN_FORMAT = "{fmt} has no temperature column; temperature left empty"

# imu_tk defaults: the Xsens MTi factory values printed by imu_tk_matlab's calibrate.m
# (README): 415 counts per m/s² (the x/z entry of diag(415, 413, 415); one nominal
# sensitivity for all axes, the fit finds the rest) and offsets 33123, 33276, 32360
# counts. imu_tk's own start guess, a mid-scale 32768, is ~100 mg off: fine for a
# fit, useless for the "before" figure.
IMU_TK_COUNTS_PER_G = 415.0 * STANDARD_GRAVITY_M_S2
IMU_TK_OFFSET_COUNTS: tuple[float, float, float] = (33123.0, 33276.0, 32360.0)
MPU6050_COUNTS_PER_G = 16384.0  # ±2 g full scale (i2cdevlib initialize() default)
FERRARIS_COUNTS_PER_G = 2048.0  # annotated imucal session: ±16 g range
FERRARIS_STATIC_PARTS: dict[str, tuple[float, float, float]] = {
    # imucal: "x_p" = x axis parallel to gravity reaction (reads +1 g), "x_a" antiparallel.
    "x_p": (1.0, 0.0, 0.0), "x_a": (-1.0, 0.0, 0.0),
    "y_p": (0.0, 1.0, 0.0), "y_a": (0.0, -1.0, 0.0),
    "z_p": (0.0, 0.0, 1.0), "z_a": (0.0, 0.0, -1.0),
}
# The most sample scatter (per axis, g rms, over the detector's window) a MEMS
# accelerometer shows while it is still. Its noise is the noise density times the root of
# its noise bandwidth: the noisiest parts in common use, MPU-6000/6050 at 400 µg/√Hz with
# their widest 260 Hz low-pass (noise bandwidth ≈ π/2 × 260 Hz), reach 400 µg × √410 ≈
# 8 mg; ADXL355 at 25 µg/√Hz, BMI088/BMI160 at 150-190 µg/√Hz, ICM-42688 at 70 µg/√Hz
# stay well below. Generous on purpose (a sensor on a table also picks up the building),
# and not derived from a datasheet per log: the real recordings' rests (docs/realdata.md)
# read 0.8-3.9 mg, up to 5x above their parts' density × √bandwidth. A vehicle in flight
# reads 40-130 mg.
STILL_NOISE_CEILING_G = 10e-3
# The ceiling is applied to the scatter of means over this span (a 10-Hz boxcar), not of
# single samples: a still part's white noise shrinks as 1/√n there (a real inclinometer's
# 7-18 mg per sample at 500 Hz is 1.2 mg), motion does not (a flight's 0.1-s means scatter
# by 31 mg in its quietest tenth). Above the sample spacing this only relaxes the ceiling:
# what was a rest stays one.
STILL_LOWPASS_S = 0.1


@dataclass
class DetectorSettings:
    """Static-interval detector settings; per-format defaults in :data:`DEFAULT_DETECTOR`."""

    window_s: float = 1.0
    threshold: float = 6.0  # × initial-rest variance magnitude
    min_duration_s: float = 1.0
    trim_s: float = 0.5


DEFAULT_DETECTOR: dict[str, DetectorSettings] = {
    # OpenAXES: ~100 Hz, the logger beeps after 3 s stillness; intervals 2.5-4 s.
    "openaxes": DetectorSettings(window_s=1.0, threshold=6.0, min_duration_s=1.5, trim_s=0.5),
    # imu_tk: Tedaldi's own test data, 100 Hz, 4-11 s per position.
    "imu_tk": DetectorSettings(window_s=1.0, threshold=6.0, min_duration_s=2.0, trim_s=0.5),
    # tomisuarez2: ~3 s per position at 100 Hz.
    "mpu6050": DetectorSettings(window_s=1.0, threshold=6.0, min_duration_s=1.5, trim_s=0.5),
    # Ferraris: the session list gives the sections; the detector is not used by default.
    "ferraris": DetectorSettings(window_s=1.0, threshold=6.0, min_duration_s=2.0, trim_s=0.5),
    # Flight-controller and table logs: a board on a bench, long still stretches.
    "ulog": DetectorSettings(window_s=1.0, threshold=6.0, min_duration_s=5.0, trim_s=0.5),
    "dataflash": DetectorSettings(window_s=1.0, threshold=6.0, min_duration_s=5.0, trim_s=0.5),
    "csv": DetectorSettings(window_s=1.0, threshold=6.0, min_duration_s=2.0, trim_s=0.5),
}


@dataclass
class RawImport:
    """Samples of one source file, converted to g on the sensor axes."""

    path: str
    fmt: str
    t_s: np.ndarray  # (N,) seconds from the first sample
    acc_g: np.ndarray  # (N,3) nominal-scale acceleration, g
    init_rest_s: float | None  # length of the initial rest the file declares, if any
    sections: list[tuple[int, int]] | None = None  # given static sections [start, end)
    section_refs: list[tuple[float, float, float]] | None = None  # ref per section, g
    notes: list[str] = field(default_factory=list)
    temp_c: np.ndarray | None = None  # (N,) the sensor's own temperature, °C, if the source has it

    @property
    def has_temperature(self) -> bool:
        return self.temp_c is not None and bool(np.any(np.isfinite(self.temp_c)))


def temperature_columns(raw: RawImport, picks: Sequence[np.ndarray]) -> dict[str, list[float]]:
    """``sensor_c`` (mean of each pick's finite temperatures) when the source has a
    temperature, else an empty ``chamber_c``: one step at an unknown temperature."""
    if not raw.has_temperature:
        return {"chamber_c": [math.nan] * len(picks)}
    assert raw.temp_c is not None
    out = []
    for idx in picks:
        seg = raw.temp_c[idx]
        seg = seg[np.isfinite(seg)]
        out.append(float(seg.mean()) if seg.size else math.nan)
    return {"sensor_c": out}


def drop_samples_without_temperature(raw: RawImport) -> RawImport:
    """A recording's temperature column is filled in every row or in none: samples whose
    temperature is missing (an empty cell, a NaN) are dropped from a source that has one,
    and the notes say how many. Nothing is interpolated."""
    if not raw.has_temperature:
        return raw
    assert raw.temp_c is not None
    keep = np.isfinite(raw.temp_c)
    if keep.all():
        return raw
    if raw.sections is not None:
        raise RecordingError(raw.path, None, None, "missing temperatures inside given sections")
    dropped = int((~keep).sum())
    return replace(raw, t_s=raw.t_s[keep], acc_g=raw.acc_g[keep], temp_c=raw.temp_c[keep],
                   notes=[*raw.notes, f"{dropped} of {keep.size} samples have no temperature: "
                          "dropped"])


def check_plausible(raw: RawImport, *, accel_fix: str, temp_fix: str, unit: str = "g",
                    counts_per_g: float | None = None) -> None:
    """Refuse a unit mistake a lab engineer would catch by eye: the median |a| of a log
    is about 1 g (:func:`calibration.gate.gravity_problem`, the one judgement of |a|, with
    the ``unit`` the numbers were read in), a die temperature is within
    :data:`PLAUSIBLE_DIE_C` (:func:`temperature_problem`)."""
    problem = gravity_problem(float(np.median(np.linalg.norm(raw.acc_g, axis=1))), unit,
                              counts_per_g)
    if problem:
        raise RecordingError(raw.path, None, None, f"{problem}: {accel_fix}")
    if raw.has_temperature:
        assert raw.temp_c is not None
        why = temperature_problem(raw.temp_c)
        if why:
            raise RecordingError(raw.path, None, None, f"{why}: {temp_fix}")


# Conversions a die temperature outside PLAUSIBLE_DIE_C is tried with, to name the mistake:
# (what the numbers would be, °C from the °C read, the --temp-unit fix).
TEMPERATURE_LOOKS: tuple[tuple[str, Callable[[float], float], str], ...] = (
    ("kelvin", lambda c: c - 273.15, "--temp-unit K"),
    ("°F", lambda c: (c - 32.0) * 5.0 / 9.0, "--temp-unit F"),
    ("hundredths of a °C", lambda c: c / 100.0,
     "--temp-unit counts --temp-c-per-count 0.01 --temp-offset-c 0"),
    ("tenths of a °C", lambda c: c / 10.0,
     "--temp-unit counts --temp-c-per-count 0.1 --temp-offset-c 0"),
    ("thousandths of a °C", lambda c: c / 1000.0,
     "--temp-unit counts --temp-c-per-count 0.001 --temp-offset-c 0"),
)
# At most this many of them are named (the first that fit, in that order).
TEMPERATURE_LOOKS_SHOWN = 2
# A die's temperature moves slowly: from one sample to the next it scatters by its
# readout's noise and last digit (0.004 … 0.5 °C: a 1 °C-resolution channel flickering
# between two codes reaches about 1 °C). An acceleration column read as the temperature
# scatters by its noise in its own unit (the inclinometer log's x axis in mg: 7 "°C").
TEMP_SAMPLE_SCATTER_MAX_C = 2.0
# Fewer samples than this: the scatter is not judged.
TEMP_SCATTER_MIN_SAMPLES = 20


def temperature_problem(temp_c: np.ndarray) -> str | None:
    """Why a temperature channel (°C, as read with the unit given) is not a die's, or None.

    Outside :data:`PLAUSIBLE_DIE_C`: the reason names the conversions in
    :data:`TEMPERATURE_LOOKS` that bring it inside, with their ``--temp-unit``. Inside it but
    scattering from one sample to the next by more than :data:`TEMP_SAMPLE_SCATTER_MAX_C`
    (robust: the median absolute successive difference, as a standard deviation, / √2):
    not a temperature (an acceleration or a gyroscope column mapped to it)."""
    finite = temp_c[np.isfinite(temp_c)]
    if finite.size == 0:
        return None
    t_lo, t_hi = float(finite.min()), float(finite.max())
    lo, hi = PLAUSIBLE_DIE_C
    if t_lo < lo or t_hi > hi:
        looks = []
        for name, conv, fix in TEMPERATURE_LOOKS:
            c_lo, c_hi = conv(t_lo), conv(t_hi)
            if lo <= c_lo and c_hi <= hi:
                looks.append(f"{name} ({c_lo:.4g} .. {c_hi:.4g} °C: {fix})")
        hint = f"; it looks like {' or '.join(looks[:TEMPERATURE_LOOKS_SHOWN])}" if looks else ""
        return (f"temperature spans {t_lo:.4g} .. {t_hi:.4g} °C, outside a die's {lo:g} .. "
                f"{hi:g} °C{hint}")
    if finite.size >= TEMP_SCATTER_MIN_SAMPLES:
        step = np.abs(np.diff(finite))
        scatter = float(1.4826 * np.median(step) / math.sqrt(2.0))
        if scatter > TEMP_SAMPLE_SCATTER_MAX_C:
            return (f"temperature scatters by {scatter:.3g} °C from one sample to the next "
                    f"(median |step| {float(np.median(step)):.3g} °C over {t_lo:.4g} .. "
                    f"{t_hi:.4g} °C); a die's reading moves by its last digit, under "
                    f"{TEMP_SAMPLE_SCATTER_MAX_C:g} °C: the column is not a temperature (an "
                    f"acceleration or a gyroscope column?)")
    return None


def vet_die_temperature(
    temp_c: np.ndarray | None, t_s: np.ndarray, channel: str, *, check_range: bool = True
) -> tuple[np.ndarray | None, str | None]:
    """The temperature channel if it reads like a die, else ``None`` and the one-line note
    saying why (for the summary a person reads).

    Not a die reading: exactly 0 °C in every sample (what PX4's and ArduPilot's simulators
    and drivers without a temperature read write), any sample outside
    :data:`PLAUSIBLE_DIE_C` (when ``check_range``; a reader whose unit the user chose
    refuses instead, :func:`check_plausible`), or one bit-identical value over a log of
    :data:`CONSTANT_TEMP_LONG_S` or longer. NaN samples are left to
    :func:`drop_samples_without_temperature`; a channel with no finite sample is ``None``
    with its own note.
    """
    if temp_c is None:
        return None, None
    finite = temp_c[np.isfinite(temp_c)]
    if finite.size == 0:
        return None, (f"{channel} is never a number (NaN: the driver has no temperature); "
                      f"temperature left empty: {NO_TEMP_CONSEQUENCE}")
    lo, hi = float(finite.min()), float(finite.max())
    span_s = float(t_s[-1] - t_s[0]) if t_s.size else 0.0
    why = None
    if lo == 0.0 and hi == 0.0:
        why = (f"is exactly 0.00 °C in all {finite.size} samples: what a simulator (SITL) "
               "or a driver without a temperature read writes, not a die reading")
    elif check_range and (lo < PLAUSIBLE_DIE_C[0] or hi > PLAUSIBLE_DIE_C[1]):
        why = (f"spans {lo:.4g} .. {hi:.4g} °C, outside a die's {PLAUSIBLE_DIE_C[0]:g} .. "
               f"{PLAUSIBLE_DIE_C[1]:g} °C: not a die temperature")
    elif lo == hi and span_s >= CONSTANT_TEMP_LONG_S:
        why = (f"is {lo:.6g} °C in all {finite.size} samples over {span_s:.0f} s: a die "
               "read this long on a powered board moves by at least its last digit, so "
               "this is a placeholder value, not a reading")
    if why is None:
        return temp_c, None
    return None, f"{channel} {why}; temperature left empty: {NO_TEMP_CONSEQUENCE}"


# --- static-interval detection ---------------------------------------------
def _window_sums(csum: np.ndarray, half: int) -> np.ndarray:
    """``csum[hi] − csum[lo]`` for every row, the centred window ``[i − half, i + half]``
    clipped to the data: slices for the interior, indices only at the two ends (the same
    subtraction per row as whole-array indexing, without three index arrays of N)."""
    n = csum.size - 1
    out = np.empty(n)
    width = 2 * half + 1
    if n > width:
        np.subtract(csum[width:], csum[: n + 1 - width], out=out[half: n - half])
        ends = np.r_[0:half, n - half:n]
    else:
        ends = np.arange(n)
    out[ends] = csum[np.minimum(ends + half + 1, n)] - csum[np.maximum(ends - half, 0)]
    return out


def _window_counts(n: int, half: int) -> np.ndarray:
    """Rows inside each row's clipped window (float, as the divisor of the sums)."""
    idx = np.arange(n)
    return (np.minimum(idx + half + 1, n) - np.maximum(idx - half, 0)).astype(float)


def _moving_variance_axes(acc: np.ndarray, window_n: int) -> Iterator[np.ndarray]:
    """Each axis' moving variance in turn, (N,), one axis alive at a time."""
    a = np.asarray(acc, float)
    n = a.shape[0]
    half = max(int(window_n) // 2, 1)
    cnt = _window_counts(n, half)
    csum = np.zeros(n + 1)
    for k in range(a.shape[1]):
        x = a[:, k] - a[0, k]
        np.cumsum(x, out=csum[1:])
        mean = _window_sums(csum, half)
        mean /= cnt
        np.multiply(x, x, out=x)
        np.cumsum(x, out=csum[1:])
        del x
        var = _window_sums(csum, half)
        var /= cnt
        var -= np.square(mean, out=mean)
        del mean
        yield np.clip(var, 0.0, None, out=var)


def moving_variance(acc: np.ndarray, window_n: int) -> np.ndarray:
    """Per-axis variance over a centred window of ``window_n`` samples, (N,3).

    Cumulative sums (of data minus its first sample, to avoid cancellation); the
    window shrinks at the ends instead of padding. One axis at a time, in place: the
    same numbers as whole-array arithmetic (a cumulative sum runs down each column
    alone), with a fraction of the temporaries (issue 20: a 2.4 M-sample log).
    """
    a = np.asarray(acc, float)
    out = np.empty(a.shape)
    for k, var in enumerate(_moving_variance_axes(a, window_n)):
        out[:, k] = var
    return out


def moving_variance_norm(acc: np.ndarray, window_n: int) -> np.ndarray:
    """‖moving variance‖ over the axes, (N,): the numbers of ``norm(moving_variance(acc),
    axis=1)`` (the squares added in axis order, as numpy's norm does for three), without
    the (N,3) array."""
    total: np.ndarray | None = None
    for var in _moving_variance_axes(acc, window_n):
        np.multiply(var, var, out=var)
        if total is None:
            total = var
        else:
            total += var
    assert total is not None
    return np.sqrt(total, out=total)


@dataclass
class StillReference:
    """What the static-interval detector compares each window's scatter with."""

    var_mag: np.ndarray  # (N,) ‖moving variance‖ of each sample's window, g²
    ref: float  # the reference ‖variance‖, g² (initial rest, or the quietest decile)
    source: str  # "initial rest" | "quietest 10 %"
    ceiling_g: float | None  # the still ceiling applied, g rms per axis (None: none)
    # The same of the STILL_LOWPASS_S means, which the ceiling is compared with (None:
    # no ceiling, not computed).
    lowpass_var_mag: np.ndarray | None = None
    lowpass_ref: float = 0.0

    @property
    def ref_rms_g(self) -> float:
        """The reference as a per-axis rms, g: √(‖(σ², σ², σ²)‖/√3) for equal axes."""
        return per_axis_rms_g(self.ref)

    @property
    def lowpass_ref_rms_g(self) -> float:
        """The reference of the :data:`STILL_LOWPASS_S` means as a per-axis rms, g."""
        return per_axis_rms_g(self.lowpass_ref)

    @property
    def is_rest(self) -> bool:
        """The reference is quiet enough to be a sensor at rest: its
        :data:`STILL_LOWPASS_S` means scatter under the ceiling."""
        return self.ceiling_g is None or self.lowpass_ref_rms_g <= self.ceiling_g

    def static(self, threshold: float) -> np.ndarray:
        """(N,) samples whose window is static: under ``threshold`` × the reference, or,
        when the reference is no rest, whose means scatter under the ceiling itself (a
        still sensor's most)."""
        if self.is_rest:
            return self.var_mag < threshold * self.ref
        assert self.ceiling_g is not None and self.lowpass_var_mag is not None
        return self.lowpass_var_mag < math.sqrt(3.0) * self.ceiling_g ** 2


def per_axis_rms_g(var_mag: float) -> float:
    """A ‖(σx², σy², σz²)‖ as the per-axis sd σ it has when the three axes are equal."""
    return math.sqrt(max(var_mag, 0.0) / math.sqrt(3.0))


def still_reference(
    t_s: np.ndarray,
    acc: np.ndarray,
    *,
    window_s: float,
    init_rest_s: float | None = None,
    ceiling_g: float | None = STILL_NOISE_CEILING_G,
) -> StillReference:
    """Each sample's window scatter and the reference the detector compares it with.

    The reference is the variance magnitude over the initial rest (the first
    ``init_rest_s`` seconds), else the 10th percentile of the moving variance (a
    recording that starts moving at once has no better one). ``ceiling_g``: the most a
    still sensor scatters (:data:`STILL_NOISE_CEILING_G`); a reference above it is not
    a rest (:attr:`StillReference.is_rest`).
    """
    t = np.asarray(t_s, float)
    a = np.asarray(acc, float)
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        raise ValueError("t_s must increase (median sample spacing is not positive)")
    window_n = max(int(round(window_s / dt)), 3)
    rest = (t < t[0] + init_rest_s) if init_rest_s is not None and init_rest_s > 0 else None
    source = "quietest 10 %" if rest is None else "initial rest"
    var_mag = moving_variance_norm(a, window_n)
    ref = _reference_variance(var_mag, a, rest)
    if ceiling_g is None:
        return StillReference(var_mag, ref, source, None)
    lowpass_n = int(round(STILL_LOWPASS_S / dt))
    low = _boxcar(a, lowpass_n) if lowpass_n > 1 else a
    low_var = moving_variance_norm(low, window_n) if lowpass_n > 1 else var_mag
    low_ref = _reference_variance(low_var, low, rest) if lowpass_n > 1 else ref
    return StillReference(var_mag, ref, source, ceiling_g, low_var, low_ref)


def _reference_variance(var_mag: np.ndarray, a: np.ndarray, rest: np.ndarray | None) -> float:
    """‖variance‖ over the initial rest (``rest``), else the quietest decile of windows."""
    if rest is not None:
        ref = float(np.linalg.norm(np.var(a[rest], axis=0))) if rest.sum() >= 3 else 0.0
    else:
        ref = float(np.percentile(var_mag, 10))
    if not ref > 0:
        ref = float(np.percentile(var_mag[var_mag > 0], 10)) if np.any(var_mag > 0) else 1e-30
    return ref


def _boxcar(a: np.ndarray, n: int) -> np.ndarray:
    """Centred ``n``-sample moving means of each column (shorter at the ends)."""
    half = n // 2
    out = np.empty_like(a, dtype=float)
    cnt = _window_counts(a.shape[0], half)
    csum = np.zeros(a.shape[0] + 1)
    for k in range(a.shape[1]):
        np.cumsum(a[:, k] - a[0, k], out=csum[1:])
        out[:, k] = _window_sums(csum, half) / cnt + a[0, k]
    return out


def detect_static_intervals(
    t_s: np.ndarray,
    acc: np.ndarray,
    *,
    window_s: float,
    threshold: float,
    min_duration_s: float,
    init_rest_s: float | None = None,
    trim_s: float = 0.0,
    ceiling_g: float | None = STILL_NOISE_CEILING_G,
) -> list[tuple[int, int]]:
    """Static intervals as ``(start_idx, end_idx)`` pairs, ``end_idx`` exclusive.

    Rule (Tedaldi/imu_tk): sample i is static when ‖moving variance‖ (window
    ``window_s``, per axis, centred) < ``threshold`` × ‖variance of the initial
    rest‖. The initial rest is the first ``init_rest_s`` seconds; without it, the
    lowest-variance decile of windows stands in. A reference above ``ceiling_g``
    (per axis rms; :data:`STILL_NOISE_CEILING_G`) is no rest, and then only windows
    under the ceiling are static (:func:`still_reference`): a log that moves from its
    first sample has no still part, not one relative to itself. Runs shorter than
    ``min_duration_s`` are dropped; ``trim_s`` is removed from each end of the
    survivors.
    """
    t = np.asarray(t_s, float)
    a = np.asarray(acc, float)
    if t.ndim != 1 or a.ndim != 2 or a.shape != (t.size, 3):
        raise ValueError(f"t_s (N,) and acc (N,3) expected, got {t.shape} and {a.shape}")
    if t.size < 3:
        return []
    if window_s <= 0 or threshold <= 0 or min_duration_s < 0 or trim_s < 0:
        raise ValueError("window_s, threshold must be > 0; min_duration_s, trim_s >= 0")
    static = still_reference(t, a, window_s=window_s, init_rest_s=init_rest_s,
                             ceiling_g=ceiling_g).static(threshold)
    edges = np.flatnonzero(np.diff(np.r_[0, static.astype(np.int8), 0]))
    out: list[tuple[int, int]] = []
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if t[end - 1] - t[start] < min_duration_s:
            continue
        s, e = _trim(t, int(start), int(end), trim_s)
        if e - s >= 3:
            out.append((s, e))
    return out


def no_still_part(raw: RawImport, settings: DetectorSettings,
                  intervals: Sequence[tuple[int, int]]) -> str | None:
    """Why the detector found no still part in ``raw``, in a person's words, or None.

    Said when ``intervals`` (the detector's) is empty because the reference is no rest
    (above :data:`STILL_NOISE_CEILING_G`): the log was recorded while the sensor moved
    or vibrated. None when there are intervals, for given sections (Ferraris), and for
    a log whose reference is a rest (then a stricter threshold finds something).
    """
    if intervals or raw.sections is not None or raw.t_s.size < 3:
        return None
    ref = still_reference(raw.t_s, raw.acc_g, window_s=settings.window_s,
                          init_rest_s=raw.init_rest_s)
    if ref.is_rest:
        return None
    assert ref.ceiling_g is not None
    return (f"no still part: the {ref.source} of the log scatters by "
            f"{ref.lowpass_ref_rms_g * 1e3:.1f} mg rms per axis in {STILL_LOWPASS_S:g}-s means "
            f"over {settings.window_s:g}-s windows ({ref.ref_rms_g * 1e3:.1f} mg sample by "
            f"sample), "
            f"above the {ref.ceiling_g * 1e3:g} mg a still accelerometer's noise reaches, and "
            f"no {settings.min_duration_s:g}-s stretch stays under {ref.ceiling_g * 1e3:g} mg: "
            f"the log was recorded while the sensor moved or vibrated (a flight, "
            f"a running motor, a hand); a calibration needs the sensor held still")


def _trim(t: np.ndarray, start: int, end: int, trim_s: float) -> tuple[int, int]:
    if trim_s <= 0:
        return start, end
    s = int(np.searchsorted(t, t[start] + trim_s, side="left"))
    e = int(np.searchsorted(t, t[end - 1] - trim_s, side="right"))
    return s, max(e, s)


# --- interval averaging ------------------------------------------------------
def intervals_to_recording(
    raw: RawImport, intervals: Sequence[tuple[int, int]], *, path: str = "<memory>"
) -> Recording:
    """One v1 row per interval: t_s = middle, mean and sample sd in g, n, position index.

    The temperature is the interval's mean ``sensor_c`` when the source has one, else
    an empty ``chamber_c`` (:func:`temperature_columns`).
    """
    if not intervals:
        raise RecordingError(raw.path, None, None, "no static interval found")
    cols: dict[str, list[float]] = {k: [] for k in (
        "t_s", "position", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z")}
    cols.update(temperature_columns(raw, [np.arange(s, e) for s, e in intervals]))
    for k, (s, e) in enumerate(intervals):
        seg = raw.acc_g[s:e]
        cols["t_s"].append(0.5 * (raw.t_s[s] + raw.t_s[e - 1]))
        cols["position"].append(float(k))
        mean = seg.mean(axis=0)
        sd = seg.std(axis=0, ddof=1) if seg.shape[0] > 1 else np.full(3, math.nan)
        for c, m, d in zip(("x", "y", "z"), mean, sd, strict=True):
            cols["a" + c].append(float(m))
            cols["sd_" + c].append(float(d))
        cols["n"].append(float(seg.shape[0]))
    if raw.section_refs is not None and len(raw.section_refs) == len(intervals):
        for j, c in enumerate(("ref_x", "ref_y", "ref_z")):
            cols[c] = [r[j] for r in raw.section_refs]
        # Labelled sections are a box turned by hand: the labels are approximate
        # (calibration/placement.py; docs/fit-honesty.md).
        cols[REF_TOL_COLUMN] = [HAND_HELD_TOL_DEG] * len(intervals)
    rec = Recording.from_columns(cols, path=path)
    rec.notes.extend(raw.notes)
    return rec


def samples_to_recording(raw: RawImport, *, path: str = "<memory>") -> Recording:
    """Raw time series: one v1 row per sample (``n`` = 1), with the sample's ``sensor_c``
    when the source has a temperature, else an empty ``chamber_c``."""
    n = raw.t_s.size
    temp = (
        {"sensor_c": raw.temp_c} if raw.has_temperature else {"chamber_c": np.full(n, math.nan)})
    cols = {
        "t_s": raw.t_s, **temp,
        "ax": raw.acc_g[:, 0], "ay": raw.acc_g[:, 1], "az": raw.acc_g[:, 2],
        "n": np.ones(n),
    }
    rec = Recording.from_columns(cols, path=path)
    rec.notes.extend(raw.notes)
    return rec


def blocks_to_recording(raw: RawImport, block_s: float, *, path: str = "<memory>") -> Recording:
    """Consecutive ``block_s``-second blocks of a time series: one row per block with the
    block's mean, sample sd, ``n`` and mean temperature (a smaller file than every
    sample, for a log that is one orientation throughout). Every block is written; the
    readers leave out a block averaged while moving (:mod:`calibration.captures`)."""
    if not (math.isfinite(block_s) and block_s > 0):
        raise RecordingError(raw.path, None, None, f"block length must be > 0 s, got {block_s}")
    k = np.floor((raw.t_s - raw.t_s[0]) / block_s).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, np.diff(k) != 0])
    bounds = list(zip(starts, np.r_[starts[1:], k.size], strict=True))
    cols: dict[str, list[float]] = {c: [] for c in (
        "t_s", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z")}
    cols.update(temperature_columns(raw, [np.arange(s, e) for s, e in bounds]))
    for s, e in bounds:
        seg = raw.acc_g[s:e]
        cols["t_s"].append(0.5 * (raw.t_s[s] + raw.t_s[e - 1]))
        sd = seg.std(axis=0, ddof=1) if seg.shape[0] > 1 else np.full(3, math.nan)
        for c, m, d in zip(("x", "y", "z"), seg.mean(axis=0), sd, strict=True):
            cols["a" + c].append(float(m))
            cols["sd_" + c].append(float(d))
        cols["n"].append(float(e - s))
    rec = Recording.from_columns(cols, path=path)
    rec.notes.extend(raw.notes)
    return rec


def find_intervals(raw: RawImport, settings: DetectorSettings) -> list[tuple[int, int]]:
    """Given sections (Ferraris session list) trimmed by ``trim_s``, else the detector."""
    if raw.sections is not None:
        return [_trim(raw.t_s, s, e, settings.trim_s) for s, e in raw.sections]
    return detect_static_intervals(
        raw.t_s, raw.acc_g, window_s=settings.window_s, threshold=settings.threshold,
        min_duration_s=settings.min_duration_s, init_rest_s=raw.init_rest_s,
        trim_s=settings.trim_s,
    )


# --- readers -----------------------------------------------------------------
OPENAXES_TEMP_COLUMN = "TEMP"


def read_openaxes(
    path: str | Path,
    *,
    sensor: str = "adxl355",
    temp_c_per_count: float | None = None,
    temp_offset_c: float | None = None,
) -> RawImport:
    """OpenAXES semicolon CSV: TIME (µs, host clock), ACCEL_<SENSOR>_0..2 in m/s² → g.

    The 40 s initial rest is the logger's documented procedure. The logger's ``TEMP``
    output (``--mode …,TEMP``) is a raw int16 whose unit the OpenAXES tools do not
    document (scale 1 in ``imu_control``): it becomes ``sensor_c`` = offset + count ×
    ``temp_c_per_count`` only when both are given, otherwise the notes say why the
    temperature was left empty.
    """
    p = str(path)
    key = sensor.strip().upper()
    if key not in ("ADXL355", "BMI160"):
        raise RecordingError(p, None, None, f"unknown sensor {sensor!r}: adxl355 or bmi160")
    header = [h.strip() for h in (_read_text(p).splitlines() or [""])[0].split(";")]
    has_temp = OPENAXES_TEMP_COLUMN in header
    cols = ("TIME", f"ACCEL_{key}_0", f"ACCEL_{key}_1", f"ACCEL_{key}_2") + (
        (OPENAXES_TEMP_COLUMN,) if has_temp else ())
    data = _read_delimited(p, ";", cols)
    time_us = data[:, 0]
    _check_monotonic(p, time_us, "TIME", first_line=2)
    t = (time_us - time_us[0]) * 1e-6
    acc = data[:, 1:4] / STANDARD_GRAVITY_M_S2
    notes = [f"OpenAXES {key}: m/s² / {STANDARD_GRAVITY_M_S2} → g"]
    temp_c = None
    if not has_temp:
        notes.append("no TEMP column (the logger's TEMP output was not enabled); "
                     "temperature left empty")
    elif temp_c_per_count is None or temp_offset_c is None:
        notes.append("TEMP column present but its unit is undocumented (raw int16); "
                     "temperature left empty: give --temp-c-per-count and --temp-offset-c")
    else:
        temp_c = temp_offset_c + data[:, 4] * temp_c_per_count
        notes.append(f"TEMP → sensor_c = {temp_offset_c:g} + count × {temp_c_per_count:g} °C")
        temp_c, why = vet_die_temperature(temp_c, t, "TEMP")
        if why:
            notes.append(why)
    return RawImport(p, "openaxes", t, acc, init_rest_s=40.0, notes=notes, temp_c=temp_c)


def read_imu_tk(
    path: str | Path,
    *,
    counts_per_g: float | Sequence[float] = IMU_TK_COUNTS_PER_G,
    offset_counts: float | Sequence[float] = IMU_TK_OFFSET_COUNTS,
    init_rest_s: float = 50.0,
) -> RawImport:
    """imu_tk ASCII (``-ascii`` .mat): 4 whitespace columns ``t ax ay az`` in counts.

    g = (counts − offset) / counts_per_g; both scalar or per axis. Defaults: the
    Xsens factory values (:data:`IMU_TK_COUNTS_PER_G`, :data:`IMU_TK_OFFSET_COUNTS`);
    imu_tk's example uses a 50 s initial rest.
    """
    p = str(path)
    scale = np.broadcast_to(np.asarray(counts_per_g, float), (3,))
    if not np.all(scale > 0):
        raise RecordingError(p, None, None, f"counts per g must be > 0, got {counts_per_g}")
    names = ("t", "ax", "ay", "az")
    rows: list[list[float]] = []
    for line_no, line in enumerate(_read_text(p).splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) != 4:
            raise RecordingError(
                p, line_no, None, f"expected 4 columns (t ax ay az), got {len(parts)}")
        rows.append([_number(p, line_no, names[i], cell) for i, cell in enumerate(parts)])
    if not rows:
        raise RecordingError(p, 1, None, "no data rows")
    data = np.asarray(rows)
    _check_monotonic(p, data[:, 0], "t", first_line=1)
    offset = np.broadcast_to(np.asarray(offset_counts, float), (3,))
    acc = (data[:, 1:4] - offset) / scale
    raw = RawImport(p, "imu_tk", data[:, 0] - data[0, 0], acc, init_rest_s=init_rest_s,
                    notes=[f"imu_tk counts: (c − {_fmt3(offset)}) / {_fmt3(scale)} → g",
                           NO_TEMP_IN_FORMAT.format(fmt="imu_tk")])
    check_plausible(raw, accel_fix="give the right --counts-per-g (and --offset)",
                    temp_fix="", unit="counts", counts_per_g=float(np.mean(scale)))
    return raw


def read_mpu6050(path: str | Path, *, counts_per_g: float = MPU6050_COUNTS_PER_G) -> RawImport:
    """tomisuarez2 CSV: ``Fs,<Hz>``, ``Logging Type``, ``Initialization time,<s|-1>``,
    ``Waiting time``, then ``ax,ay,az,gx,gy,gz`` in counts; t = i / Fs."""
    p = str(path)
    lines = _read_text(p).splitlines()
    if len(lines) < 6:
        raise RecordingError(
            p, len(lines) + 1, None, "expected a 4-line preamble, a header and data")
    meta: dict[str, float] = {}
    for i in range(4):
        parts = lines[i].split(",")
        if len(parts) != 2:
            raise RecordingError(p, i + 1, None, f"preamble line must be 'key,value': {lines[i]!r}")
        meta[parts[0].strip().lower()] = _number(p, i + 1, parts[0].strip(), parts[1])
    fs = meta.get("fs")
    if fs is None or not fs > 0:
        raise RecordingError(p, 1, "Fs", "sampling rate 'Fs' missing or not positive")
    data = _read_delimited(p, ",", ("ax", "ay", "az"), text="\n".join(lines[4:]), line_offset=4)
    t = np.arange(data.shape[0]) / fs
    init = meta.get("initialization time", -1.0)
    return RawImport(p, "mpu6050", t, data / counts_per_g,
                     init_rest_s=init if init > 0 else None,
                     notes=[f"MPU-6050 counts / {counts_per_g:g} → g, t = i / {fs:g} Hz",
                            "gx, gy, gz (the gyroscope) not read",
                            NO_TEMP_IN_FORMAT.format(fmt="this MPU-6050 CSV")])


def read_ferraris(
    path: str | Path,
    *,
    session_list: str | Path | None = None,
    counts_per_g: float = FERRARIS_COUNTS_PER_G,
    rate_hz: float | None = None,
) -> RawImport:
    """imucal Ferraris session.

    * session CSV (``n_samples, …, acc_x..z`` in m/s², 102.4 Hz) with a session-list
      JSON (``{"x_p": {"start", "end"}, …}``; default: ``<stem>_list.json`` beside it);
    * or the annotated CSV (``part, samples, acc_x..z`` in counts, 204.8 Hz).

    Only the six static parts (±x, ±y, ±z) become sections; their known gravity
    direction is kept as ``ref_*`` (the rotation parts are not static).
    """
    p = str(path)
    text = _read_text(p)
    header = [h.strip() for h in text.splitlines()[0].split(",")] if text else []
    if "part" in header:
        return _read_ferraris_annotated(p, text, counts_per_g, rate_hz or 204.8)
    data = _read_delimited(p, ",", ("acc_x", "acc_y", "acc_z"), text=text)
    fs = rate_hz or 102.4
    default_list = Path(p).with_name(Path(p).stem + "_list.json")
    list_path = Path(session_list) if session_list else default_list
    try:
        spec = json.loads(list_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RecordingError(str(list_path), None, None, "session list JSON not found") from None
    except json.JSONDecodeError as exc:
        raise RecordingError(str(list_path), exc.lineno, None, f"invalid JSON: {exc.msg}") from None
    sections, refs = [], []
    for part, ref in FERRARIS_STATIC_PARTS.items():
        entry = spec.get(part) if isinstance(spec, dict) else None
        if not isinstance(entry, dict) or "start" not in entry or "end" not in entry:
            raise RecordingError(str(list_path), None, part, "missing {start, end} for this part")
        s, e = int(entry["start"]), int(entry["end"])
        if not 0 <= s < e <= data.shape[0]:
            raise RecordingError(str(list_path), None, part,
                                 f"section [{s}, {e}) outside the {data.shape[0]} samples")
        sections.append((s, e))
        refs.append(ref)
    order = np.argsort([s for s, _ in sections])
    return RawImport(
        p, "ferraris", np.arange(data.shape[0]) / fs, data / STANDARD_GRAVITY_M_S2, None,
        sections=[sections[i] for i in order], section_refs=[refs[i] for i in order],
        notes=[f"Ferraris session: m/s² / {STANDARD_GRAVITY_M_S2} → g, t = i / {fs:g} Hz, "
               f"sections from {list_path.name}",
               NO_TEMP_IN_FORMAT.format(fmt="a Ferraris session")],
    )


def _read_ferraris_annotated(p: str, text: str, counts_per_g: float, fs: float) -> RawImport:
    reader = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(reader)]
    for name in ("part", "acc_x", "acc_y", "acc_z"):
        if name not in header:
            raise RecordingError(p, 1, name, "required column missing")
    ip = header.index("part")
    idx = [header.index(c) for c in ("acc_x", "acc_y", "acc_z")]
    parts: list[str] = []
    rows: list[list[float]] = []
    for line_no, row in enumerate(reader, start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise RecordingError(
                p, line_no, None, f"has {len(row)} cells, header has {len(header)}")
        parts.append(row[ip].strip())
        rows.append([_number(p, line_no, header[i], row[i]) for i in idx])
    data = np.asarray(rows) / counts_per_g
    sections, refs = [], []
    for part, ref in FERRARIS_STATIC_PARTS.items():
        hit = np.flatnonzero(np.asarray(parts) == part)
        if hit.size == 0:
            raise RecordingError(p, None, "part", f"no rows for static part {part!r}")
        if hit[-1] - hit[0] + 1 != hit.size:
            raise RecordingError(p, int(hit[0]) + 2, "part", f"part {part!r} is not contiguous")
        sections.append((int(hit[0]), int(hit[-1]) + 1))
        refs.append(ref)
    order = np.argsort([s for s, _ in sections])
    return RawImport(
        p, "ferraris", np.arange(data.shape[0]) / fs, data, None,
        sections=[sections[i] for i in order], section_refs=[refs[i] for i in order],
        notes=[f"Ferraris annotated: counts / {counts_per_g:g} → g, t = i / {fs:g} Hz "
               "(parts are concatenated, so t_s is not wall time)",
               NO_TEMP_IN_FORMAT.format(fmt="a Ferraris session")],
    )


def read_source(fmt: str, path: str | Path, **options: object) -> RawImport:
    """Dispatch on ``fmt`` (one of :data:`FORMATS`); options go to the reader."""
    # Imported here: those modules build on this one (RawImport, the parsing helpers).
    from calibration import importers_logs, importers_table

    readers = {"openaxes": read_openaxes, "imu_tk": read_imu_tk,
               "ferraris": read_ferraris, "mpu6050": read_mpu6050,
               "ulog": importers_logs.read_ulog, "dataflash": importers_logs.read_dataflash,
               "csv": importers_table.read_table}
    if fmt not in readers:
        raise RecordingError(str(path), None, None,
                             f"unknown import format {fmt!r}; expected one of {', '.join(FORMATS)}")
    return readers[fmt](path, **options)  # type: ignore[operator]


def import_static(
    fmt: str, path: str | Path, settings: DetectorSettings | None = None, **options: object
) -> tuple[RawImport, list[tuple[int, int]], Recording]:
    """Read, detect and average: the whole import in one call (used by CLI and benchmarks)."""
    raw = read_source(fmt, path, **options)
    st = settings or DEFAULT_DETECTOR[fmt]
    intervals = find_intervals(raw, st)
    return raw, intervals, intervals_to_recording(raw, intervals, path=str(path))


# --- parsing helpers ---------------------------------------------------------
def _fmt3(v: np.ndarray) -> str:
    return f"{v[0]:g}" if np.all(v == v[0]) else "(" + ", ".join(f"{x:g}" for x in v) + ")"


def _read_text(p: str) -> str:
    try:
        return Path(p).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise RecordingError(p, None, None, "file not found") from None
    except IsADirectoryError:
        raise RecordingError(p, None, None, "is a directory, expected a file") from None
    except UnicodeDecodeError as exc:
        raise RecordingError(p, None, None, f"not UTF-8 text ({exc.reason})") from None


# A cell like "21,973": a spreadsheet's decimal comma, not a garbled line (the whole table
# is written so). Said in the refusal, with the fix.
DECIMAL_COMMA = "a decimal comma"
_DECIMAL_COMMA_CELL = re.compile(r"[+-]?\d*,\d+([eE][+-]?\d+)?")


def _number(p: str, line_no: int, column: str, cell: str) -> float:
    try:
        v = float(cell.strip())
    except ValueError:
        why = (f" ({DECIMAL_COMMA}: numbers are read with '.' as the decimal mark; write "
               f"the table with '.' decimals, e.g. export it with ';' or tab between "
               f"cells and '.' in numbers)" if _DECIMAL_COMMA_CELL.fullmatch(cell.strip())
               else "")
        raise RecordingError(p, line_no, column,
                             f"not a number: {cell.strip()!r}{why}") from None
    if not math.isfinite(v):
        raise RecordingError(p, line_no, column, f"not a finite number: {cell.strip()!r}")
    return v


def _read_delimited(
    p: str, delimiter: str, columns: Sequence[str], *, text: str | None = None,
    line_offset: int = 0,
) -> np.ndarray:
    """Numeric columns by header name from a delimited text; errors name line and column.

    A plain body is parsed by numpy's C reader (:mod:`calibration.importers_plain`: the
    same numbers); anything else, and every row to refuse, by the csv module row by row.
    """
    body = _read_text(p) if text is None else text
    plain = bool(body) and is_plain(body)
    cut = body.find("\n") + 1
    # a plain first line alone reads as it does from the whole text (no copy of it all)
    reader = csv.reader([body[:cut] if cut else body] if plain else io.StringIO(body),
                        delimiter=delimiter)
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise RecordingError(
            p, line_offset + 1, None, "empty file: expected a header row") from None
    for c in columns:
        if c not in header:
            raise RecordingError(p, line_offset + 1, c,
                                 f"required column missing (header: {delimiter.join(header)})")
    idx = [header.index(c) for c in columns]
    if plain:
        values = parse_plain_rows(body, cut or len(body), delimiter, len(header), idx)
        if values is not None:
            return values
        reader = csv.reader(io.StringIO(body), delimiter=delimiter)
        next(reader)
    rows: list[list[float]] = []
    for k, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        line_no = line_offset + k
        if len(row) != len(header):
            raise RecordingError(
                p, line_no, None, f"has {len(row)} cells, header has {len(header)}")
        rows.append([_number(p, line_no, columns[j], row[i]) for j, i in enumerate(idx)])
    if not rows:
        raise RecordingError(p, line_offset + 2, None, "no data rows after the header")
    return np.asarray(rows, dtype=float)


def _check_monotonic(p: str, t: np.ndarray, column: str, *, first_line: int) -> None:
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise RecordingError(
            p, first_line + i, column, f"time goes backwards ({t[i]} after {t[i - 1]})")
