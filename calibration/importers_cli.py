"""``soakcal import``: another tool's log → recording format v1.

``soakcal import --format openaxes|imu_tk|ferraris|mpu6050|ulog|dataflash|csv RAW -o REC.csv
[--min-static-s S] [--threshold X] [--raw] [--block-s S]``

Static multi-position formats (openaxes, imu_tk, ferraris, mpu6050) are written as one
row per static interval by default; the logs of a board warming at one orientation
(ulog, dataflash, csv: :data:`calibration.importers.LOG_FORMATS`) as every sample.
``--raw`` writes every sample, ``--block-s S`` one row per consecutive S-second block.
The sensor's temperature is kept as ``sensor_c`` wherever the source has one; the
summary's notes say what could not be read.

The argparse wiring lives in ``service/cli.py``; :func:`run_import` takes its
Namespace. Attributes: ``format``, ``raw_path``, ``output``, ``min_static_s``,
``threshold``, ``raw`` (the ``--raw`` flag); a Namespace whose positional is
``raw`` (the path) with the flag in ``raw_samples`` works too. Optional ones (read with ``getattr``
so the wiring may add them later): ``sensor`` (openaxes: adxl355|bmi160),
``counts_per_g`` and ``offset`` (imu_tk: one number or ``x,y,z``),
``session_list`` (ferraris JSON), ``window_s``, ``trim_s``.

Unless ``--threshold`` and ``--trim-s`` are both given, the missing ones are chosen by
leave-one-interval-out error over a grid (:mod:`calibration.static_choice`) and the
summary says what was chosen. Exit 0 and a summary on stdout; exit 2 with one line on
stderr for bad input, and then no file is written (the write is the last step and atomic).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from typing import TextIO

import numpy as np

from calibration import importers
from calibration.errors import CalibrationError, RecordingError
from calibration.recording import Recording, write_recording

# An interval longer than this is a log at rest while something drifts (a warm-up), not
# a hand-placed position: its noise is estimated from sample-to-sample differences.
DRIFT_INTERVAL_S = 60.0


def run_import(args: argparse.Namespace, out: TextIO | None = None) -> int:
    """Run one import; returns the process exit code (0 ok, 2 bad input)."""
    out = out or sys.stdout
    try:
        fmt = str(args.format)
        if fmt not in importers.FORMATS:
            raise CalibrationError(
                f"unknown --format {fmt!r}; expected one of {', '.join(importers.FORMATS)}")
        settings = _settings(args, fmt)
        src, raw_rows = _source_and_mode(args)
        block_s = getattr(args, "block_s", None)
        if fmt in importers.LOG_FORMATS and block_s is None:
            raw_rows = True
        raw = importers.drop_samples_without_temperature(
            importers.read_source(fmt, src, **_reader_options(args, fmt)))
        choice = None
        if raw_rows or block_s is not None:  # the intervals only feed the summary
            intervals = importers.find_intervals(raw, settings)
        else:
            # Imported here: it brings the fit and scipy (1 s), which a log import never uses.
            from calibration import static_choice

            # Threshold and trim by leave-one-interval-out error unless the flags fix them.
            fixed = frozenset(f for a, f in (("threshold", "threshold"), ("trim_s", "trim_s"))
                              if getattr(args, a, None) is not None)
            choice = static_choice.choose_detector(raw, settings, fixed=fixed)
            intervals = choice.intervals
        still_why = importers.no_still_part(
            raw, choice.settings if choice is not None else settings, intervals)
        if still_why is not None and not (raw_rows or block_s is not None):
            raise RecordingError(raw.path, None, None, f"no static interval found: {still_why}")
        if block_s is not None:
            rec = importers.blocks_to_recording(raw, float(block_s), path=str(args.output))
        elif raw_rows:
            rec = importers.samples_to_recording(raw, path=str(args.output))
        else:
            rec = importers.intervals_to_recording(raw, intervals, path=str(args.output))
        write_recording(args.output, rec)
    except (CalibrationError, OSError, ValueError) as exc:
        print(f"soakcal import: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    kind = ("rows (one per block)" if block_s is not None
            else "raw sample rows" if raw_rows else "rows (one per static interval)")
    print(summary(raw, intervals, rec, str(args.output), kind=kind, no_still=still_why),
          file=out)
    if choice is not None:
        print(choice.summary(), file=out)
    return 0


def _source_and_mode(args: argparse.Namespace) -> tuple[str, bool]:
    """(input path, write raw sample rows?) from either Namespace layout.

    The brief's layout is ``raw_path`` (str) + ``raw`` (bool, ``--raw``); a wiring
    whose positional is named ``raw`` carries the path there and the flag as
    ``raw_samples``.
    """
    path = getattr(args, "raw_path", None)
    flag = getattr(args, "raw", False)
    if path is None and isinstance(flag, str):
        return flag, bool(getattr(args, "raw_samples", False))
    if path is None:
        raise CalibrationError("no RAW input file given")
    return str(path), bool(flag) or bool(getattr(args, "raw_samples", False))


def summary(
    raw: importers.RawImport,
    intervals: list[tuple[int, int]],
    rec: Recording,
    output: str,
    *,
    kind: str = "rows (one per static interval)",
    no_still: str | None = None,
) -> str:
    """Human summary: intervals, durations, per-axis noise (µg), |g| range of the means,
    the temperature kept (or why none), what was written. ``no_still``: why no interval
    is still (:func:`calibration.importers.no_still_part`), said on the intervals line."""
    lines = [f"{raw.path} ({raw.fmt}): {raw.t_s.size} samples over {raw.t_s[-1]:.1f} s"]
    lines += [f"  note: {n}" for n in raw.notes]
    dur = np.array([raw.t_s[e - 1] - raw.t_s[s] for s, e in intervals])
    lines.append(f"static intervals: {len(intervals)}"
                 + (f": {no_still}" if no_still else ""))
    if dur.size:
        lines.append(f"  duration s: min {dur.min():.2f}  median {np.median(dur):.2f}  "
                     f"max {dur.max():.2f}")
        n = np.array([e - s for s, e in intervals])
        if dur.max() > DRIFT_INTERVAL_S:
            # a warm-up drifts inside its one long interval: its sd would be the drift
            sd = np.array([np.diff(raw.acc_g[s:e], axis=0).std(axis=0, ddof=1) / np.sqrt(2.0)
                           for s, e in intervals])
            how = " (successive differences / √2: the slow drift removed)"
        else:
            sd = np.array([raw.acc_g[s:e].std(axis=0, ddof=1) for s, e in intervals])
            how = ""
        noise_ug = np.median(sd, axis=0) * 1e6
        floor_ug = np.median(sd / np.sqrt(n)[:, None], axis=0) * 1e6
        lines.append(f"  noise per sample{how}, median µg: " + _xyz(noise_ug))
        lines.append("  noise of each mean (sd/√n), median µg: " + _xyz(floor_ug, 2))
        means = np.array([raw.acc_g[s:e].mean(axis=0) for s, e in intervals])
        g = np.linalg.norm(means, axis=1)
        lines.append(f"  |g| of interval means: {g.min():.6f} .. {g.max():.6f} g "
                     "(nominal scale, uncalibrated)")
    if raw.has_temperature:
        assert raw.temp_c is not None
        tc = raw.temp_c[np.isfinite(raw.temp_c)]
        lines.append(f"temperature (sensor_c): {tc.min():.2f} .. {tc.max():.2f} °C, "
                     f"{tc.size} of {raw.temp_c.size} samples")
        lines.append(f"wrote {len(rec)} {kind} to {output}")
    else:
        lines.append(f"wrote {len(rec)} {kind} to {output}; temperature columns empty "
                     "(no temperature read: one step at unknown temperature)")
    return "\n".join(lines)


def _settings(args: argparse.Namespace, fmt: str) -> importers.DetectorSettings:
    st = importers.DEFAULT_DETECTOR[fmt]
    changes: dict[str, float] = {}
    for attr, field in (("min_static_s", "min_duration_s"), ("threshold", "threshold"),
                        ("window_s", "window_s"), ("trim_s", "trim_s")):
        v = getattr(args, attr, None)
        if v is None:
            continue
        v = float(v)
        if not np.isfinite(v) or v < 0 or (field in ("threshold", "window_s") and v == 0):
            raise CalibrationError(f"--{attr.replace('_', '-')} must be a positive number, "
                                   f"got {v}")
        changes[field] = v
    return replace(st, **changes)


def _reader_options(args: argparse.Namespace, fmt: str) -> dict[str, object]:
    opts: dict[str, object] = {}
    if fmt == "openaxes" and getattr(args, "sensor", None):
        opts["sensor"] = str(args.sensor)
    if fmt == "imu_tk":
        if getattr(args, "counts_per_g", None) is not None:
            opts["counts_per_g"] = _numbers(args.counts_per_g, "--counts-per-g")
        if getattr(args, "offset", None) is not None:
            opts["offset_counts"] = _numbers(args.offset, "--offset")
    if fmt == "ferraris" and getattr(args, "session_list", None):
        opts["session_list"] = str(args.session_list)
    if fmt == "openaxes":
        for attr in ("temp_c_per_count", "temp_offset_c"):
            if getattr(args, attr, None) is not None:
                opts[attr] = float(getattr(args, attr))
    if fmt in ("ulog", "dataflash") and getattr(args, "instance", None) is not None:
        opts["instance"] = int(args.instance)
    if fmt == "csv":
        opts.update(_table_options(args))
    return opts


def _table_options(args: argparse.Namespace) -> dict[str, object]:
    """``--columns``, ``--delimiter`` and the units of ``--format csv``."""
    from calibration.importers_table import TableUnits

    def opt(name: str, default: object = None) -> object:
        v = getattr(args, name, None)
        return default if v is None else v

    counts = opt("counts_per_g")
    offset = opt("offset")
    units = TableUnits(
        accel=opt("accel_unit"),  # type: ignore[arg-type]
        counts_per_g=None if counts is None else _numbers(counts, "--counts-per-g"),
        offset_counts=0.0 if offset is None else _numbers(offset, "--offset"),
        temp=str(opt("temp_unit", "C")),
        temp_c_per_count=opt("temp_c_per_count"),  # type: ignore[arg-type]
        temp_offset_c=opt("temp_offset_c"),  # type: ignore[arg-type]
        time=str(opt("time_unit", "s")),
        rate_hz=opt("rate_hz"),  # type: ignore[arg-type]
        bad_lines=str(opt("bad_lines", "refuse")),
    )
    delim = opt("delimiter")
    if delim == "tab":
        delim = "\t"
    return {"columns": opt("columns"), "units": units, "delimiter": delim}


def _numbers(value: object, flag: str) -> float | tuple[float, ...]:
    """One number or ``x,y,z`` (string or sequence)."""
    items = value.split(",") if isinstance(value, str) else (
        list(value) if isinstance(value, list | tuple) else [value])
    try:
        nums = tuple(float(v) for v in items)
    except (TypeError, ValueError):
        raise CalibrationError(f"{flag} expects a number or x,y,z, got {value!r}") from None
    if len(nums) not in (1, 3) or not all(np.isfinite(nums)):
        raise CalibrationError(f"{flag} expects a number or x,y,z, got {value!r}")
    return nums[0] if len(nums) == 1 else nums


def _xyz(v: np.ndarray, digits: int = 0) -> str:
    return "  ".join(f"{c} {x:.{digits}f}" for c, x in zip("xyz", v, strict=True))


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__
