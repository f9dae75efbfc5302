"""Where the suite finds public real recordings from other labs.

Recordings whose licence allows it are vendored under ``tests/data/realdata/`` (each folder
keeps the source's README with its origin, commit and licence). Others — the OpenAXES ADXL355
log, whose data licence is not stated — are read only when ``SOAKCAL_REALDATA`` names a folder
holding them, laid out the same way; tests that need them skip with that reason otherwise.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

VENDORED = Path(__file__).parent / "data" / "realdata"
ENV = "SOAKCAL_REALDATA"


def realdata(rel: str) -> Path | None:
    """The file ``rel`` (``folder/file``) from the vendored copy or ``$SOAKCAL_REALDATA``."""
    for root in (VENDORED, os.environ.get(ENV)):
        if root and (Path(root) / rel).is_file():
            return Path(root) / rel
    return None


def need_realdata(rel: str) -> Path:
    """``realdata(rel)``, or skip the calling test saying how to provide the file."""
    path = realdata(rel)
    if path is None:
        pytest.skip(f"real recording {rel} is not vendored (licence not stated); "
                    f"set {ENV} to a folder holding it to run this test")
    return path
