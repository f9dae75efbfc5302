"""Recording format v1 (spec/recording.md) rendered from the measurements table."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable

from service.db.models import Measurement

RECORDING_COLUMNS: tuple[str, ...] = (
    "t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position",
    "ref_x", "ref_y", "ref_z", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z",
)  # fmt: skip


def render_recording_csv(measurements: Iterable[Measurement]) -> str:
    """Header plus one row per measurement; ``None`` becomes an empty cell ("not recorded")."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(RECORDING_COLUMNS)
    for m in measurements:
        writer.writerow([_cell(getattr(m, column)) for column in RECORDING_COLUMNS])
    return out.getvalue()


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)  # shortest text that round-trips exactly
    return str(value)
