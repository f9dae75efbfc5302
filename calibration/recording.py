"""Recording format v1 (``shared/spec/recording.md``): read, validate, write.

A :class:`Recording` keeps every column as a float array (NaN = empty cell)
plus the raw text cells, so commands that copy rows through (``compensate``)
keep unknown columns and formatting exactly. Every rejection names the file,
the 1-based line and the column.
"""

from __future__ import annotations

import csv
import io
import math
import os
import tempfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.errors import RecordingError

REQUIRED = ("t_s", "ax", "ay", "az")
TEMPERATURE = ("sensor_c", "chamber_c")
NUMERIC = (
    "t_s", "ax", "ay", "az", "chamber_c", "sensor_c", "ref_x", "ref_y", "ref_z",
    "step", "setpoint_c", "position", "n", "sd_x", "sd_y", "sd_z",
)
# Order used when soakcal writes a recording (readers accept any order).
CANONICAL_ORDER = (
    "t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position",
    "ref_x", "ref_y", "ref_z", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z",
)
DEFAULT_RANGE_G = 8.0  # ADXL355's widest range; a reading beyond it cannot be real


@dataclass
class Recording:
    """Columns of a v1 recording. ``columns[name]`` is a float array (NaN = not recorded)."""

    columns: dict[str, np.ndarray]
    header: list[str]
    path: str = "<memory>"
    cells: list[list[str]] | None = None  # raw text rows, for copy-through
    notes: list[str] = field(default_factory=list)  # conditioning applied, said in reports

    # --- construction -------------------------------------------------
    @classmethod
    def from_columns(
        cls, columns: Mapping[str, Iterable[float]], path: str = "<memory>"
    ) -> Recording:
        cols = {k: np.asarray(list(v) if not isinstance(v, np.ndarray) else v, dtype=float)
                for k, v in columns.items()}
        header = [c for c in CANONICAL_ORDER if c in cols] + [
            c for c in cols if c not in CANONICAL_ORDER
        ]
        rec = cls(columns=cols, header=header, path=path)
        validate(rec)
        return rec

    # --- access ---------------------------------------------------------
    def __len__(self) -> int:
        return len(self.columns["t_s"])

    def has(self, name: str) -> bool:
        """Column present and at least one cell filled."""
        col = self.columns.get(name)
        return col is not None and bool(np.any(np.isfinite(col)))

    @property
    def t_s(self) -> np.ndarray:
        return self.columns["t_s"]

    @property
    def raw_g(self) -> np.ndarray:
        return np.column_stack([self.columns[c] for c in ("ax", "ay", "az")])

    @property
    def has_reference(self) -> bool:
        return all(self.has(c) for c in ("ref_x", "ref_y", "ref_z"))

    @property
    def ref_g(self) -> np.ndarray | None:
        if not self.has_reference:
            return None
        return np.column_stack([self.columns[c] for c in ("ref_x", "ref_y", "ref_z")])

    @property
    def sigma_g(self) -> np.ndarray | None:
        """Standard error of each averaged reading, sd/√n (g), where recorded."""
        if not all(self.has(c) for c in ("sd_x", "sd_y", "sd_z")):
            return None
        sd = np.column_stack([self.columns[c] for c in ("sd_x", "sd_y", "sd_z")])
        n = self.columns.get("n")
        if n is None or not np.any(np.isfinite(n)):
            return sd
        n = np.where(np.isfinite(n) & (n > 0), n, 1.0)
        return sd / np.sqrt(n)[:, None]

    @property
    def has_temperature(self) -> bool:
        return self.has("sensor_c") or self.has("chamber_c")

    @property
    def temperature_source(self) -> str:
        return "sensor_c" if self.has("sensor_c") else "chamber_c"

    def temperature_c(self) -> np.ndarray:
        """Thermal-model temperature: ``sensor_c`` where filled, else ``chamber_c`` (spec rule)."""
        if self.has("sensor_c"):
            t = self.columns["sensor_c"].copy()
            if "chamber_c" in self.columns:
                gaps = ~np.isfinite(t)
                t[gaps] = self.columns["chamber_c"][gaps]
            return t
        return self.columns["chamber_c"].copy()

    def steps(self) -> np.ndarray:
        """Step index per row: ``step`` column, else setpoint changes, else temperature plateaus."""
        if self.has("step"):
            return np.nan_to_num(self.columns["step"], nan=-1).astype(int)
        if self.has("setpoint_c"):
            return _runs(self.columns["setpoint_c"], tol=1e-9)
        return _plateaus(self.temperature_c())

    def positions(self) -> np.ndarray:
        if self.has("position"):
            return np.nan_to_num(self.columns["position"], nan=-1).astype(int)
        steps = self.steps()
        pos = np.zeros(len(self), int)
        for s in np.unique(steps):
            idx = np.flatnonzero(steps == s)
            pos[idx] = np.arange(idx.size)
        return pos

    def subset(self, mask: np.ndarray) -> Recording:
        cols = {k: v[mask] for k, v in self.columns.items()}
        cells = None
        if self.cells is not None:
            cells = [row for row, keep in zip(self.cells, mask, strict=True) if keep]
        return Recording(cols, list(self.header), self.path, cells, list(self.notes))


# --- reading --------------------------------------------------------------
def read_recording(path: str | os.PathLike, *, range_g: float = DEFAULT_RANGE_G) -> Recording:
    """Read and validate a v1 CSV. Raises :class:`RecordingError` naming file, line, column."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RecordingError(str(p), None, None, "file not found") from None
    except UnicodeDecodeError as exc:
        raise RecordingError(str(p), None, None, f"not UTF-8 text ({exc.reason})") from None
    return parse_recording(text, str(p), range_g=range_g)


def parse_recording(
    text: str, path: str = "<memory>", *, range_g: float = DEFAULT_RANGE_G
) -> Recording:
    reader = csv.reader(io.StringIO(text.lstrip("\ufeff")))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise RecordingError(path, 1, None, "empty file: expected a header row") from None
    for name in REQUIRED:
        if name not in header:
            raise RecordingError(
                path, 1, name, f"required column missing (header: {','.join(header)})"
            )
    if not any(t in header for t in TEMPERATURE):
        raise RecordingError(path, 1, "chamber_c", "needs a chamber_c or sensor_c column")
    dup = {h for h in header if header.count(h) > 1}
    if dup:
        raise RecordingError(path, 1, sorted(dup)[0], "column appears twice in the header")
    numeric_idx = [(i, h) for i, h in enumerate(header) if h in NUMERIC]
    values: dict[str, list[float]] = {h: [] for _, h in numeric_idx}
    cells: list[list[str]] = []
    for line_no, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue  # blank line: tolerated (trailing newline)
        if len(row) != len(header):
            raise RecordingError(
                path, line_no, None, f"has {len(row)} cells, header has {len(header)}"
            )
        for i, h in numeric_idx:
            cell = row[i].strip()
            if cell == "":
                values[h].append(math.nan)
                continue
            try:
                v = float(cell)
            except ValueError:
                raise RecordingError(path, line_no, h, f"not a number: {cell!r}") from None
            if not math.isfinite(v):
                raise RecordingError(path, line_no, h, f"not a finite number: {cell!r}")
            values[h].append(v)
        cells.append(row)
    if not cells:
        raise RecordingError(path, 2, None, "no data rows after the header")
    cols = {h: np.asarray(v, dtype=float) for h, v in values.items()}
    rec = Recording(columns=cols, header=header, path=path, cells=cells)
    validate(rec, range_g=range_g, first_line=2)
    return rec


def validate(rec: Recording, *, range_g: float = DEFAULT_RANGE_G, first_line: int = 2) -> None:
    """Spec rules: required values present, t_s non-decreasing, readings within range."""
    path = rec.path
    n = len(rec.columns["t_s"])
    for name in REQUIRED:
        col = rec.columns[name]
        if len(col) != n:
            raise RecordingError(path, None, name, f"has {len(col)} values, t_s has {n}")
        missing = np.flatnonzero(~np.isfinite(col))
        if missing.size:
            line = first_line + int(missing[0])
            raise RecordingError(path, line, name, "required value is empty")
    back = np.flatnonzero(np.diff(rec.columns["t_s"]) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise RecordingError(
            path, first_line + i, "t_s",
            f"time goes backwards ({rec.columns['t_s'][i]} after {rec.columns['t_s'][i - 1]})",
        )
    for name in ("ax", "ay", "az"):
        over = np.flatnonzero(np.abs(rec.columns[name]) > range_g)
        if over.size:
            i = int(over[0])
            raise RecordingError(
                path, first_line + i, name,
                f"reading {rec.columns[name][i]} g is outside the sensor range ±{range_g} g",
            )
    if not any(t in rec.columns for t in TEMPERATURE):
        raise RecordingError(path, None, "chamber_c", "needs a chamber_c or sensor_c column")
    temp = rec.temperature_c()
    empty = np.flatnonzero(~np.isfinite(temp))
    # A recording with no temperature at all (imports from labs without a temperature
    # channel) is one step at an unknown temperature; a gap in an otherwise
    # temperature-bearing recording is an error.
    if empty.size and empty.size < temp.size:
        raise RecordingError(
            path, first_line + int(empty[0]), rec.temperature_source,
            "no temperature in this row (neither sensor_c nor chamber_c)",
        )


# --- writing --------------------------------------------------------------
def write_recording(
    path: str | os.PathLike, rec: Recording | Mapping[str, Iterable[float]]
) -> None:
    """Write a v1 CSV atomically (temp file + rename): a crash never leaves half a file."""
    if not isinstance(rec, Recording):
        rec = Recording.from_columns(rec)
    header = rec.header
    rows = zip(*(rec.columns[h] for h in header), strict=True)
    atomic_write_text(path, _csv_text(header, rows))


def recording_text(rec: Recording) -> str:
    return _csv_text(rec.header, zip(*(rec.columns[h] for h in rec.header), strict=True))


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", dir=p.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def format_value(v: float, name: str = "") -> str:
    if not math.isfinite(v):
        return ""
    if name in ("step", "position", "n") and float(v).is_integer():
        return str(int(v))
    return repr(float(v))


def _csv_text(header: list[str], rows: Iterable[Iterable[float]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow([format_value(v, h) for v, h in zip(row, header, strict=True)])
    return buf.getvalue()


def _runs(values: np.ndarray, tol: float) -> np.ndarray:
    change = np.r_[False, np.abs(np.diff(np.nan_to_num(values))) > tol]
    return np.cumsum(change)


def _plateaus(temp_c: np.ndarray, jump_c: float = 2.0) -> np.ndarray:
    """Steps from temperature plateaus: a new step where T moves more than ``jump_c`` from
    the running mean of the current plateau."""
    steps = np.zeros(temp_c.size, int)
    start, k = 0, 0
    for i in range(1, temp_c.size):
        if abs(temp_c[i] - np.mean(temp_c[start:i])) > jump_c:
            k += 1
            start = i
        steps[i] = k
    return steps
