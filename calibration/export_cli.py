"""``soakcal export MODEL.json --format c|json-flat|px4|ardupilot -o OUT``.

Contract: ``docs/model-file.md`` (c, json-flat) and ``docs/firmware-export.md`` (px4,
ardupilot: ``--instance N``, ``--device-id ID``, ``--rate-term fold|drop``,
``--temperature-reading filtered|per-sample``); what a firmware cannot express is
written in the file's header and, one line each, on stderr.

Exit 0 on success; exit 2 with one line on stderr for a bad model file, an
unknown format or an unwritable output, in which case nothing is written.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from calibration.errors import CalibrationError
from calibration.export import FORMATS, export_text, firmware_export
from calibration.model_file import load_model_file
from calibration.recording import atomic_write_text

EXIT_OK = 0
EXIT_BAD_INPUT = 2


def run_export(args: argparse.Namespace) -> int:
    """Write the firmware export of ``args.model`` to ``args.output``."""
    fmt = getattr(args, "format", None) or "c"
    if fmt not in FORMATS:
        return _fail(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    model_path, out_path = Path(args.model), Path(args.output)
    if out_path.exists() and model_path.exists() and os.path.samefile(model_path, out_path):
        return _fail(f"{out_path}: the output would overwrite the model file; choose another -o")
    try:
        model, conditioning = load_model_file(model_path)
        limitations: list[str] = []
        reading: list[str] = []
        if fmt in ("px4", "ardupilot"):
            rate_term = getattr(args, "rate_term", None) or "fold"
            if rate_term not in ("fold", "drop"):
                return _fail(f"--rate-term: expected fold or drop, got {rate_term!r}")
            if rate_term == "drop":
                # the model's own b(T), as a model file without the fold exports it: the
                # header's DROPPED line says what the rate term did on the fit log
                model.provenance.pop("rate_fold", None)
            fw = firmware_export(model, fmt, source_name=model_path.name,
                                 instance=getattr(args, "instance", None),
                                 device_id=int(getattr(args, "device_id", None) or 0),
                                 temperature_reading=getattr(args, "temperature_reading",
                                                             None))
            text, limitations, reading = fw.text, fw.limitations, fw.reading
        else:
            text = export_text(model, fmt, source_name=model_path.name,
                               conditioning=conditioning)
    except CalibrationError as exc:  # ModelFileError included
        return _fail(str(exc))
    try:
        atomic_write_text(out_path, text)
    except OSError as exc:
        return _fail(f"{out_path}: cannot write ({exc.strerror or exc})")
    for line in reading:
        # a model fitted in a rebuilt temperature, applied at the firmware's own reading
        print(line if line.startswith("WARNING") else f"note: {fmt} at its own temperature "
              f"reading: {line}", file=sys.stderr)
    for line in limitations:
        print(f"warning: {fmt} cannot express: {line}", file=sys.stderr)
    print(f"exported {model_path} as {fmt} -> {out_path}")
    return EXIT_OK


def _fail(message: str) -> int:
    print(f"error: {' '.join(message.split())}", file=sys.stderr)
    return EXIT_BAD_INPUT
