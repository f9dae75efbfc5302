"""``soakcal export MODEL.json --format c|json-flat -o OUT`` (contract: ``docs/model-file.md``).

Exit 0 on success; exit 2 with one line on stderr for a bad model file, an
unknown format or an unwritable output, in which case nothing is written.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from calibration.errors import CalibrationError
from calibration.export import FORMATS, export_text
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
        text = export_text(model, fmt, source_name=model_path.name, conditioning=conditioning)
    except CalibrationError as exc:  # ModelFileError included
        return _fail(str(exc))
    try:
        atomic_write_text(out_path, text)
    except OSError as exc:
        return _fail(f"{out_path}: cannot write ({exc.strerror or exc})")
    print(f"exported {model_path} as {fmt} -> {out_path}")
    return EXIT_OK


def _fail(message: str) -> int:
    print(f"error: {' '.join(message.split())}", file=sys.stderr)
    return EXIT_BAD_INPUT
