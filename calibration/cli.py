"""``soakcal calibrate`` and ``soakcal compensate`` (contract: ``docs/cli.md``).

The argparse wiring lives in ``service/cli.py``; these functions take its
Namespace and return the exit status: 0 on success, 2 with one line on stderr
for bad input, in which case no output file is written (every check runs
before the single atomic write).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path

import numpy as np

from calibration import fitting, gate
from calibration.captures import (
    capture_means,
    capture_temperature_c,
    placed_samples,
    warmup_captures,
)
from calibration.errors import CalibrationError, RecordingError
from calibration.fitting import CalibrationFit, FitOptions, OptionNotApplicable
from calibration.gravity import GravityError, LocalGravity, from_arguments
from calibration.model_file import load_model_file, save_model
from calibration.recording import Recording, atomic_write_text, read_recording
from calibration.temperature_conditioning import (
    CompensationConditioning,
    compensation_temperature,
    smooth_over_time,
)
from calibration.thermal import DEFAULT_METHOD, METHODS, ThermalModel

OUTPUT_COLUMNS = ("cx", "cy", "cz")
EXIT_OK = 0
EXIT_BAD_INPUT = 2


def run_calibrate(args: argparse.Namespace) -> int:
    """Calibrate ``args.recording`` (:func:`calibration.fitting.fit`) and write ``args.output``."""
    method = getattr(args, "method", None) or DEFAULT_METHOD
    if method not in METHODS:
        return _fail(f"--method: expected one of {', '.join(METHODS)}, got {method!r}")
    try:
        gravity = _local_gravity(args)
    except GravityError as exc:
        return _fail(str(exc))
    try:
        rate_gain = _rate_gain(getattr(args, "rate_gain_ug_per_c_per_min", None))
    except ValueError as exc:
        return _fail(f"--rate-gain-ug-per-c-per-min: {exc}")
    options = FitOptions(method=getattr(args, "method", None), gravity=gravity,
                         rate_gain_ug_per_c_per_min=rate_gain)
    try:
        rec = read_recording(args.recording, raw_cells=False)  # no copy-through
        fit = fitting.fit(rec, options)
    except RecordingError as exc:
        return _fail(str(exc))
    except OptionNotApplicable as exc:
        return _fail(f"--{exc.option.replace('_', '-')}: {exc}")
    except CalibrationError as exc:
        return _fail(f"{args.recording}: {exc}")
    try:
        save_model(args.output, fit.model)
    except OSError as exc:
        return _fail(f"{args.output}: cannot write the model file ({exc.strerror or exc})")
    if fit.kind == "warmup":
        return _report_warmup(args, fit)
    if fit.kind == "continuous":
        return _report_continuous(args, fit)
    from calibration import holdout, report  # matplotlib is only needed from here on

    rec = fit.recording
    report.add_sections(fit, rec)  # coefficients, and Table 5 for reference recordings

    figures: list[Path] = []
    report_dir = getattr(args, "report_dir", None)
    if report_dir:
        figures = report.write_figures(fit, rec, report_dir)
    if getattr(args, "json", False):
        doc = report.report_dict(fit)
        doc["model_file"] = str(args.output)
        doc["figures"] = [str(p) for p in figures]
        holdout.add_holdout(doc, rec, fit)  # loo_rmse_ug, dof, warnings (calibration/holdout.py)
        print(json.dumps(doc, indent=2, allow_nan=False))
    else:
        print(report.format_table6(fit))
        print(holdout.format_holdout(holdout.holdout_fields(rec, fit)))
        print(f"\nmodel written to {args.output}")
        for p in figures:
            print(f"figure: {p}")
    return EXIT_OK


def _report_continuous(args: argparse.Namespace, fit: CalibrationFit) -> int:
    """The ramp fit's report (calibration/ramp_report.py): per temperature band, not per step."""
    from calibration.ramp_report import format_ramp_report

    if getattr(args, "report_dir", None):
        fit.report.setdefault("notes", []).append(
            "figures are drawn for soak (step) fits only; none for a continuous fit")
    if getattr(args, "json", False):
        doc = dict(fit.report, model_file=str(args.output), figures=[])
        print(json.dumps(doc, indent=2, allow_nan=False))
    else:
        print(format_ramp_report(fit))
        print(f"\nmodel written to {args.output}")
    return EXIT_OK


def _report_warmup(args: argparse.Namespace, fit: CalibrationFit) -> int:
    """A warm-up's report (calibration/warmup.py): each axis' bias change with temperature."""
    from calibration.warmup import format_warmup

    if getattr(args, "report_dir", None):
        fit.report["notes"].append("--report-dir: no figures are drawn for a warm-up; the "
                                   "report is this text (or --json)")
    if getattr(args, "json", False):
        doc = dict(fit.report)
        doc["model_file"] = str(args.output)
        doc["figures"] = []
        print(json.dumps(doc, indent=2, allow_nan=False))
    else:
        print(format_warmup(fit.report))
        for note in fit.report["notes"]:
            print(f"note: {note}")
        print(f"\nmodel written to {args.output}")
    return EXIT_OK


def run_diagnose(args: argparse.Namespace) -> int:
    """``soakcal diagnose``: the gate first (calibration/gate.py), then the diagnosis.

    Data the gate does not let an SFEM be fitted to (one orientation, a warm-up, no
    spare degrees of freedom) get "cannot judge" with calibrate's reason, in the
    diagnosis' own text and JSON forms; everything else goes to
    :func:`calibration.discrepancy.cli.run_diagnose` with the recording already read.
    """
    from calibration.discrepancy import cli as discrepancy_cli

    try:
        rec = read_recording(args.recording, raw_cells=False)  # no copy-through
    except RecordingError as exc:
        return _fail(str(exc))
    why = gate.cannot_judge(rec)
    if why is None:
        # raw rows without positions: the placements calibrate fits (rows taken while the
        # sensor moved left out), not every sample as its own position
        rec = placed_samples(rec, capture_means(rec))
        return int(discrepancy_cli.run_diagnose(args, rec))  # read once (issue 22)
    from calibration.discrepancy.diagnose import _cannot_judge
    from calibration.discrepancy.level import ALPHA, N_NULL

    diag = _cannot_judge(rec, why, int(getattr(args, "n_null", None) or N_NULL), ALPHA, [])
    print(diag.to_json() if getattr(args, "json", False) else diag.report())
    return EXIT_OK


def _rate_gain(text: str | None) -> tuple[float, float, float] | None:
    """``X,Y,Z`` (µg per °C/min, finite) → (x, y, z), or None when not given."""
    if text is None:
        return None
    try:
        k = np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise ValueError(f"expected three numbers X,Y,Z, got {text!r}") from None
    if k.shape != (3,) or not np.all(np.isfinite(k)):
        raise ValueError(f"expected three finite numbers X,Y,Z, got {text!r}")
    return (float(k[0]), float(k[1]), float(k[2]))


def _local_gravity(args: argparse.Namespace) -> LocalGravity | None:
    """``--gravity-g`` or ``--latitude-deg``/``--height-m`` (GravityError when implausible)."""
    return from_arguments(getattr(args, "gravity_g", None), getattr(args, "latitude_deg", None),
                          getattr(args, "height_m", None))


def run_compensate(args: argparse.Namespace) -> int:
    """Apply ``args.model`` to ``args.recording``; write every input column plus cx, cy, cz."""
    try:
        model, conditioning = load_model_file(args.model)
        rec = read_recording(args.recording)
    except CalibrationError as exc:  # ModelFileError, RecordingError
        return _fail(str(exc))
    try:
        gate.check_gravity(rec.raw_g, "nothing written")
        gate.check_temperature_channels(rec, "nothing written")
    except CalibrationError as exc:
        return _fail(f"{args.recording}: {exc}")
    clash = [c for c in OUTPUT_COLUMNS if c in rec.header]
    if clash:
        return _fail(str(RecordingError(
            rec.path, 1, clash[0], "the input already has this output column; "
            "compensate would overwrite it")))
    if getattr(args, "raw_temperature", False) and getattr(args, "smooth_temperature_s", None):
        return _fail("--raw-temperature and --smooth-temperature-s are alternatives; give one")
    extrapolate = bool(getattr(args, "extrapolate", False))
    try:
        temp_c, how = _temperatures(model, rec, extrapolate, args, conditioning)
        cal = model.compensate(rec.raw_g, temp_c, extrapolate=True)
    except CalibrationError as exc:
        return _fail(str(exc))
    if model.temperature_rate:
        cal = cal - _rate_offset_rows(model, rec)
        how += ("; the warm-up's rate term k·dT/dt applied (dT/dt from the capture-mean "
                f"temperatures over {float(model.temperature_rate['window_s']):g} s)")
    try:
        atomic_write_text(args.output, _output_csv(rec, cal))
    except OSError as exc:
        return _fail(f"{args.output}: cannot write ({exc.strerror or exc})")
    print(f"compensated {len(rec)} rows with {model.model_version} ({model.mode} mode) "
          f"-> {args.output}")
    print(how)
    return EXIT_OK


def _temperatures(
    model: ThermalModel,
    rec: Recording,
    extrapolate: bool,
    args_smooth: object = None,
    conditioning: CompensationConditioning | None = None,
) -> tuple[np.ndarray, str]:
    """The model's temperature for each row and how it was obtained (one line).

    By default the temperature is conditioned as the model file says
    (:func:`compensation_temperature`: per step where the recording has steps,
    the causal filter otherwise). ``--raw-temperature`` uses each row's own
    reading; ``--smooth-temperature-s S`` a centred local line over S seconds
    (:func:`smooth_over_time`). RecordingError for missing/out-of-range ones.
    """
    if not model.temperature_dependent:
        return np.full(len(rec), np.nan), "temperature: not used (temperature-independent model)"
    if not rec.has_temperature:
        raise RecordingError(
            rec.path, None, "sensor_c",
            "no temperature in the recording, but the model depends on temperature",
        )
    temp_c = rec.temperature_c()
    smooth_s = getattr(args_smooth, "smooth_temperature_s", None) or 0.0
    if getattr(args_smooth, "raw_temperature", False):
        how = "temperature: each row's own reading, not conditioned (--raw-temperature)"
    elif smooth_s > 0:
        temp_c = smooth_over_time(rec.t_s, temp_c, float(smooth_s))
        how = f"temperature smoothed by a centred local line over {float(smooth_s):g} s"
    elif model.mode == "warmup" or (
            (caps := capture_means(rec)).is_raw and not (rec.has("step") or rec.has("setpoint_c"))):
        # A warm-up is fitted in each capture's own mean temperature, and so are raw
        # samples of a continuous log: each row gets its capture's (linear in time
        # between captures); an averaged reading is its own capture.
        caps = capture_means(rec)
        means, rebuilt = (warmup_captures(caps.recording) if model.mode == "warmup"
                          else (caps.recording, None))
        temp_c = capture_temperature_c(rec, caps, means)
        how = ("temperature: raw samples read as capture means (calibrate's reader); each "
               "row at its capture's mean temperature, linear in time between captures "
               "(--raw-temperature: use each row's own reading)" if caps.is_raw else
               "temperature: each reading's own, as the warm-up model was fitted")
        if rebuilt:
            how += f"; {rebuilt}"
    else:
        temp_c, how = compensation_temperature(
            rec.t_s, temp_c,
            rec.columns["step"] if rec.has("step") else None,
            rec.columns["setpoint_c"] if rec.has("setpoint_c") else None,
            conditioning or CompensationConditioning())
        how += " (--raw-temperature: use each row's own reading)"
    if model.temperature_source in ("sensor_c", "chamber_c") and \
            rec.temperature_source != model.temperature_source:
        print(f"warning: the model was fitted on {model.temperature_source} but "
              f"{rec.path} only has {rec.temperature_source}; offsets between the two "
              f"channels go uncompensated", file=sys.stderr)
    if not extrapolate:
        i = model.first_out_of_range(temp_c)
        if i is not None:
            lo, hi = model.valid_c  # type: ignore[misc]
            raise RecordingError(
                rec.path, i + 2, rec.temperature_source,
                f"temperature {temp_c[i]:.2f} °C is outside the model's valid range "
                f"[{lo:.2f}, {hi:.2f}] °C (use --extrapolate to compensate anyway)",
            )
    return temp_c, how


def _rate_offset_rows(model: ThermalModel, rec: Recording) -> np.ndarray:
    """(N,3) a warm-up model's rate term at each row, g: dT/dt read from the capture means
    as calibrate read it, linear in time between captures."""
    from calibration.warmup import rate_offset_g

    means, _ = warmup_captures(capture_means(rec).recording)
    off = rate_offset_g(model, means.t_s, means.temperature_c())
    return np.column_stack([np.interp(rec.t_s, means.t_s, off[:, i]) for i in range(3)])


def _output_csv(rec: Recording, cal_g: np.ndarray) -> str:
    """Input rows verbatim (raw cell text) plus cx, cy, cz."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(rec.header) + list(OUTPUT_COLUMNS))
    cells = rec.cells
    if cells is None:  # an in-memory recording: format its numbers
        from calibration.recording import format_value

        cells = [[format_value(rec.columns[h][i], h) for h in rec.header]
                 for i in range(len(rec))]
    for row, c in zip(cells, cal_g, strict=True):
        w.writerow(list(row) + [f"{v:.10f}" for v in c])
    return buf.getvalue()


def _fail(message: str) -> int:
    print(f"error: {' '.join(message.split())}", file=sys.stderr)
    return EXIT_BAD_INPUT
