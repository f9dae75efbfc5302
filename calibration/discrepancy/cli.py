"""``soakcal diagnose`` (docs/cli.md): ``run_diagnose(args) -> exit code``.

``args`` carries: recording (path), model (path or None), json (bool),
report_dir (path or None), seed (int), n_null (int). Bad input: one line on
stderr, exit 2, nothing written.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from calibration.discrepancy.level import N_NULL
from calibration.errors import CalibrationError, RecordingError


def run_diagnose(args: Any, rec: Any = None) -> int:
    """``rec``: the recording already read (by the gate in ``calibration.cli``), so a large
    file is parsed once; None reads ``args.recording`` here."""
    from calibration.discrepancy.diagnose import diagnose
    from calibration.recording import read_recording

    if rec is None:
        try:
            rec = read_recording(args.recording, raw_cells=False)
        except RecordingError as exc:
            print(str(exc), file=sys.stderr)
            return 2
    model = None
    model_path = getattr(args, "model", None)
    if model_path:
        try:
            from calibration.model_file import load_model

            model = load_model(model_path)
        except (CalibrationError, OSError, ValueError) as exc:
            print(f"{model_path}: {exc}", file=sys.stderr)
            return 2
    n_null = int(getattr(args, "n_null", N_NULL) or N_NULL)
    if n_null < 10:
        print(f"--n-null must be at least 10, got {n_null}", file=sys.stderr)
        return 2
    against = getattr(args, "against", None)
    if getattr(args, "write_twin", None) and not against:
        print("--write-twin needs --against FILE (the twin to correct)", file=sys.stderr)
        return 2
    if against:
        return _run_against(args, rec, against, n_null)
    try:
        diag = diagnose(rec, model, seed=int(getattr(args, "seed", 0) or 0), n_null=n_null,
                        progress=progress_printer(len(rec)))
    except (CalibrationError, ValueError, np_linalg_error()) as exc:
        print(f"{args.recording}: cannot diagnose: {exc}", file=sys.stderr)
        return 2
    if getattr(args, "json", False):
        print(diag.to_json())
    else:
        print(diag.report())
    report_dir = getattr(args, "report_dir", None)
    if report_dir:
        from calibration.discrepancy.report import write_diagnosis_figures

        out = Path(report_dir)
        write_diagnosis_figures(diag, out)
        (out / "diagnosis.json").write_text(diag.to_json(), encoding="utf-8")
        (out / "diagnosis.txt").write_text(diag.report() + "\n", encoding="utf-8")
        if model_path:
            from calibration.discrepancy.extensions import write_extended_model

            write_extended_model(diag, model_path, str(out / "model_extended.json"))
    return 0


# From this many readings a diagnosis takes long enough (~10 s and up; ~8 min at 1 M) that
# its steps are shown on stderr as it works (stdout keeps the report or the JSON alone).
PROGRESS_MIN_READINGS = 20_000


def progress_printer(n_readings: int) -> Callable[[str], None] | None:
    """One stderr line per step of a long diagnosis, with the time since it began; None
    (nothing shown) below :data:`PROGRESS_MIN_READINGS` readings."""
    if n_readings < PROGRESS_MIN_READINGS:
        return None
    t0 = time.monotonic()  # elapsed time shown, nothing waited on

    def show(line: str) -> None:
        print(f"diagnose [{time.monotonic() - t0:6.0f} s] {line}", file=sys.stderr, flush=True)

    return show


def _run_against(args: Any, rec: Any, against: str, n_null: int) -> int:
    """``diagnose --against FILE``: the given model or twin held fixed (docs/diagnosis.md §9)."""
    from calibration.discrepancy.against import diagnose_against
    from calibration.discrepancy.twin_file import load_model_or_twin, save_twin

    try:
        twin = load_model_or_twin(against)
    except (CalibrationError, OSError) as exc:
        print(str(exc), file=sys.stderr)
        return 2
    try:
        diag = diagnose_against(rec, twin, against=str(against), n_null=n_null,
                                seed=int(getattr(args, "seed", 0) or 0))
    except (CalibrationError, ValueError, np_linalg_error()) as exc:
        print(f"{args.recording}: cannot diagnose against {against}: {exc}", file=sys.stderr)
        return 2
    print(diag.to_json() if getattr(args, "json", False) else diag.report())
    out = getattr(args, "write_twin", None)
    if out and diag.corrected is not None:
        save_twin(out, diag.corrected)
    report_dir = getattr(args, "report_dir", None)
    if report_dir:
        d = Path(report_dir)
        d.mkdir(parents=True, exist_ok=True)
        (d / "diagnosis.json").write_text(diag.to_json(), encoding="utf-8")
        (d / "diagnosis.txt").write_text(diag.report() + "\n", encoding="utf-8")
    return 0


def np_linalg_error() -> type[Exception]:
    import numpy as np

    return np.linalg.LinAlgError
