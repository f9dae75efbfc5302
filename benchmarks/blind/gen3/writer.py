"""Write gen3 rows as a recording-v1 CSV (docs/recording.md) with the csv module (issue 22:
the generator does not go through the project's own writer)."""

from __future__ import annotations

import csv
from pathlib import Path

from benchmarks.blind.gen3.case import ROW_COLUMNS

_FORMATS = {"t_s": "{:.3f}", "step": "{:d}", "setpoint_c": "{:.1f}", "chamber_c": "{:.2f}",
            "sensor_c": "{:.5f}", "position": "{:d}", "n": "{:d}"}


def cell(name: str, value: float) -> str:
    fmt = _FORMATS.get(name)
    if fmt is None:
        return f"{value:.10g}" if name.startswith("sd_") else f"{value:.9f}"
    return fmt.format(int(value) if fmt == "{:d}" else float(value))


def write_csv(rows: list[dict[str, float]], path: str | Path,
              sensor_lsb_c: float | None = None) -> None:
    """The rows' recording columns; with ``sensor_lsb_c`` also that column on every row
    (docs/recording.md: the channel's LSB, for a channel quantised without dither)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(ROW_COLUMNS + (() if sensor_lsb_c is None else ("sensor_lsb_c",)))
        extra = [] if sensor_lsb_c is None else [f"{sensor_lsb_c:g}"]
        for r in rows:
            w.writerow([cell(c, r[c]) for c in ROW_COLUMNS] + extra)
