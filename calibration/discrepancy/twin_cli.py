"""``soakcal twin fit RECORDING -o TWIN.json`` (docs/cli.md): ``run_twin_fit(args)``.

Bad input: one line on stderr naming the file, exit 2, nothing written.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np

from calibration.errors import CalibrationError, RecordingError


def run_twin_fit(args: Any) -> int:
    from calibration.discrepancy.twin_file import save_twin
    from calibration.discrepancy.twin_fit import fit_twin, report_text
    from calibration.recording import read_recording

    try:
        rec = read_recording(args.recording, raw_cells=False)
    except RecordingError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    try:
        twin, report = fit_twin(rec, effects=not getattr(args, "no_effects", False))
    except (CalibrationError, ValueError, np.linalg.LinAlgError) as exc:
        print(f"{args.recording}: cannot fit a twin: {exc}", file=sys.stderr)
        return 2
    save_twin(args.output, twin)
    if getattr(args, "json", False):
        print(json.dumps(report, indent=2, ensure_ascii=False))
    else:
        print(report_text(report, str(args.output)))
    return 0
