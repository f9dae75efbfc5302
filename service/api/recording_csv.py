"""Recording format v1 (docs/recording.md) rendered from the measurements table."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable

from calibration.table_pose import POSE_COLUMNS
from service.db.models import Measurement, SoakProbe

RECORDING_COLUMNS: tuple[str, ...] = (
    "t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position", "visit",
    "ref_x", "ref_y", "ref_z", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z",
)  # fmt: skip


def render_recording_csv(measurements: Iterable[Measurement],
                         ref_tol_deg: float | None = None) -> str:
    """Header plus one row per measurement; ``None`` becomes an empty cell ("not recorded").

    ``measurements`` come in time order; ``visit`` (a project column, docs/recording.md)
    is each row's 0-based index within its step in that order: with a position order
    other than the schedule's (``position_order``), what tells time in the plateau
    apart from the position.
    ``ref_tol_deg``: the references were hand-placed (a manual fixture) with about this
    orientation uncertainty; written on every row so a refit treats them as approximate
    (docs/recording.md, ``ref_tol_deg``), as the campaign's own calibration did.
    ``pose_qw, pose_qx, pose_qy, pose_qz`` (docs/recording.md, project additions): the
    pose the rig commanded for each reading, after ``ref_z``, written only when some row
    has one (empty cells on the others): a campaign without poses (a hand-placed fixture,
    rows stored before migration 0009) exports exactly as before.
    """
    rows = list(measurements)
    columns = _with_pose(rows)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    extra = () if ref_tol_deg is None else ("ref_tol_deg",)
    writer.writerow(columns + extra)
    tail = [] if ref_tol_deg is None else [_cell(float(ref_tol_deg))]
    visits: dict[int, int] = {}  # rows written so far per step
    for m in rows:
        visit = visits.get(m.step, 0)
        visits[m.step] = visit + 1
        writer.writerow([_cell(visit if column == "visit" else getattr(m, column))
                         for column in columns] + tail)
    return out.getvalue()


def _with_pose(rows: list[Measurement]) -> tuple[str, ...]:
    """:data:`RECORDING_COLUMNS`, with :data:`POSE_COLUMNS` after ``ref_z`` when any row
    has a pose."""
    if not any(getattr(m, "pose_qw", None) is not None for m in rows):
        return RECORDING_COLUMNS
    at = RECORDING_COLUMNS.index("ref_z") + 1
    return RECORDING_COLUMNS[:at] + POSE_COLUMNS + RECORDING_COLUMNS[at:]


# The soak probes (docs/recording.md, "Project additions"): recording-v1 columns, no
# position (a probe is taken wherever the table stands during the soak, at home when the
# rate gain is measured) and no per-axis sd.
PROBE_COLUMNS: tuple[str, ...] = (
    "t_s", "step", "setpoint_c", "chamber_c", "sensor_c",
    "ref_x", "ref_y", "ref_z", "ax", "ay", "az", "n",
)  # fmt: skip


def render_probes_csv(probes: Iterable[SoakProbe]) -> str:
    """Header plus one row per soak probe; ``None`` becomes an empty cell."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(PROBE_COLUMNS)
    for p in probes:
        writer.writerow([_cell(getattr(p, column)) for column in PROBE_COLUMNS])
    return out.getvalue()


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)  # shortest text that round-trips exactly
    return str(value)
