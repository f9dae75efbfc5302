"""A generic delimited table with a column map and units (``soakcal import --format csv``).

The map names which source column holds what (``--columns
t=TIME,ax=AX,ay=AY,az=AZ,temp=DIE_T``; unnamed roles keep their defaults ``t_s``,
``ax``, ``ay``, ``az``, ``temp_c``). Units are never guessed: the acceleration unit
is required (``g``, ``mg``, ``m/s2``, or ``counts`` with ``--counts-per-g`` and
optionally ``--offset``), the temperature unit defaults to ``C`` (``C``, ``F``, ``K``,
or ``counts`` with ``--temp-c-per-count`` and ``--temp-offset-c``), the time unit to
``s`` (``s``, ``ms``, ``us``). Without a time column, ``--rate-hz`` gives t = i / rate.
A line that is not a row of the table (a serial log's garbled line: two records run
together, a record cut short) is refused, naming it; ``--bad-lines skip`` leaves such lines
out instead, each named in the notes, as long as they are a few (:data:`MAX_BAD_FRACTION`).
A result a lab engineer would catch by eye is refused
(:func:`calibration.importers.check_plausible`): a median |a| far from 1 g names the
unit it looks like.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from itertools import islice
from pathlib import Path

import numpy as np

from calibration.errors import RecordingError
from calibration.gate import G_PER_UNIT
from calibration.importers import (
    DECIMAL_COMMA,
    RawImport,
    _check_monotonic,
    _fmt3,
    _number,
    _read_text,
    check_plausible,
    vet_die_temperature,
)
from calibration.importers_plain import head_lines, is_plain, parse_plain_rows

ROLES: tuple[str, ...] = ("t", "ax", "ay", "az", "temp")
DEFAULT_COLUMNS: dict[str, str] = {
    "t": "t_s", "ax": "ax", "ay": "ay", "az": "az", "temp": "temp_c"}
# g per unit of each acceleration unit ("counts" goes through counts_per_g).
ACCEL_UNITS: dict[str, float] = G_PER_UNIT
TEMP_UNITS: tuple[str, ...] = ("C", "F", "K", "counts")
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
# Leading lines searched for the start of the table (a logger's banner, a row cut short:
# :func:`_leading_banner`), the lines after a start that must line up with it, and how many
# characters of each skipped line the import notes show.
BANNER_MAX_LINES = 20
BANNER_CONFIRM_LINES = 3
BANNER_SHOWN_CHARS = 24
# ``--bad-lines skip`` is for a garbled line here and there: beyond this fraction of the
# lines the table itself is misread (a delimiter, a column map), and skipping would hide it.
MAX_BAD_FRACTION = 0.01
BAD_LINES_SHOWN = 5
BAD_LINES = ("refuse", "skip")


@dataclass(frozen=True)
class TableUnits:
    """How to read the numbers of a table (see the module docstring)."""

    accel: str | None = None
    counts_per_g: float | Sequence[float] | None = None
    offset_counts: float | Sequence[float] = 0.0
    temp: str = "C"
    temp_c_per_count: float | None = None
    temp_offset_c: float | None = None
    time: str = "s"
    rate_hz: float | None = None
    bad_lines: str = "refuse"  # or "skip": garbled lines left out, each named


def parse_column_map(text: str | None) -> dict[str, str]:
    """``"t=TIME,ax=AX,…"`` → {role: column}; unknown roles and empty names are errors."""
    out = dict(DEFAULT_COLUMNS)
    if not text:
        return out
    for item in text.split(","):
        role, sep, name = item.partition("=")
        role, name = role.strip(), name.strip()
        if not sep or role not in ROLES or not name:
            raise ValueError(f"--columns: expected ROLE=COLUMN with ROLE one of "
                             f"{', '.join(ROLES)}, got {item.strip()!r}")
        out[role] = name
    return out


def read_table(
    path: str | Path,
    *,
    columns: Mapping[str, str] | str | None = None,
    units: TableUnits | None = None,
    delimiter: str | None = None,
) -> RawImport:
    """Read a delimited table (delimiter sniffed among ``, ; tab`` unless given)."""
    p = str(path)
    u = units or TableUnits()
    cmap = parse_column_map(columns) if columns is None or isinstance(columns, str) else {
        **DEFAULT_COLUMNS, **dict(columns)}
    _check_units(p, u)
    text = _read_text(p)
    # Only the leading lines: splitting a log of millions of rows cost 230 MB here.
    head, lines = head_lines(text, BANNER_MAX_LINES, BANNER_CONFIRM_LINES)
    if not lines:
        raise RecordingError(p, 1, None, "empty file: expected a header row")
    notes: list[str] = []
    skip = _leading_banner(lines, delimiter)
    if skip:
        shown = ", ".join(repr(line[:BANNER_SHOWN_CHARS]) for line in lines[:skip])
        notes.append(f"{skip} leading line(s) skipped before the table (not rows of it: a "
                     f"banner, or a row cut short; they begin {shown})")
        text = text[sum(map(len, head.splitlines(keepends=True)[:skip])):]
    del head
    delim = delimiter or _sniff(lines[skip])
    plain = is_plain(text)
    if plain:  # the first line alone: csv reads it as it would read it from the whole text
        cut = text.find("\n") + 1
        header_row = next(csv.reader([text[:cut] if cut else text], delimiter=delim))
    else:
        header_row = next(csv.reader(io.StringIO(text), delimiter=delim))
    header = [h.strip() for h in header_row]
    first_line = skip + 2
    if _all_numbers(header):
        # No header row: columns are named by their position, 1 first; the row is data.
        header = [str(i) for i in range(1, len(header) + 1)]
        first_line = skip + 1
        notes.append(f"no header row: columns named by position 1..{len(header)}")
    where = (f"header: {delim.join(header)}" if first_line == skip + 2 else
             f"the file has no header row: name columns by position 1..{len(header)}")
    wanted = ["ax", "ay", "az"]
    if cmap["t"] in header:
        wanted.insert(0, "t")
    elif u.rate_hz is None:
        raise RecordingError(p, 1, cmap["t"], "time column missing: name it with --columns "
                             f"t=NAME or give --rate-hz ({where})")
    else:
        notes.append(f"no time column: t = i / {u.rate_hz:g} Hz")
    has_temp = cmap["temp"] in header
    if has_temp:
        wanted.append("temp")
    else:
        notes.append(f"no temperature column {cmap['temp']!r} (--columns temp=NAME); "
                     "temperature left empty")
    for role in ("ax", "ay", "az"):
        if cmap[role] not in header:
            raise RecordingError(p, 1, cmap[role], f"column missing (--columns {role}=NAME; "
                                 f"{where})")
    _check_distinct_columns(p, cmap, wanted)
    if "t" in wanted:
        _check_time_unit_name(p, cmap["t"], u.time)
    idx = [header.index(cmap[r]) for r in wanted]
    has_header = first_line == skip + 2
    data = None
    if plain:  # numpy's C reader; None where the per-cell reader must decide
        data = parse_plain_rows(text, (cut or len(text)) if has_header else 0, delim,
                                len(header), idx,
                                empty_is_nan=wanted.index("temp") if has_temp else None)
    if data is None:
        data, bad = _parse_cells(p, text, delim, header, wanted, idx, first_line=first_line,
                                 has_header=has_header, skip_bad=u.bad_lines == "skip")
        if bad:
            notes.append(_bad_lines_note(bad, data.shape[0], timed="t" in wanted))
    del text
    if "t" not in wanted:  # with a time column a block written twice goes back in time
        _check_no_repeated_block(p, data)
    # each column its own array: a view would keep the whole table alive with the temperature
    col = {r: data[:, k].copy() for k, r in enumerate(wanted)}
    n_rows = data.shape[0]
    del data
    if "t" in col:
        _check_monotonic(p, col["t"], cmap["t"], first_line=first_line)
        t = (col["t"] - col["t"][0]) * TIME_UNITS[u.time]
    else:
        assert u.rate_hz is not None
        t = np.arange(n_rows) / u.rate_hz
    acc_raw = np.column_stack([col["ax"], col["ay"], col["az"]])
    acc, acc_note = _to_g(acc_raw, u)
    notes.insert(0, acc_note)
    temp_c = None
    if has_temp:
        temp_c, temp_note = _to_c(col["temp"], u)
        notes.append(temp_note)
    raw = RawImport(p, "csv", t, acc, init_rest_s=None, notes=notes, temp_c=temp_c)
    cpg = float(np.mean(np.asarray(u.counts_per_g, float))) if u.accel == "counts" else None
    check_plausible(raw, accel_fix=("give the right --counts-per-g" if u.accel == "counts"
                                    else "give the right --accel-unit"),
                    temp_fix=f"give the right --temp-unit, or check --columns temp= "
                    f"(column {cmap['temp']!r} was read)", unit=str(u.accel),
                    counts_per_g=cpg)
    # The range was checked above with the unit's hint; what is left: a 0 or a constant.
    vetted, why = vet_die_temperature(temp_c, t, f"temperature column {cmap['temp']!r}",
                                      check_range=False)
    if why:
        raw = replace(raw, temp_c=vetted, notes=[*notes, why])
    return raw


SKIP_HINT = ("a garbled line of a serial log? --bad-lines skip leaves such lines out, "
             "each named")


def _parse_cells(
    p: str, text: str, delim: str, header: Sequence[str], wanted: Sequence[str],
    idx: Sequence[int], *, first_line: int, has_header: bool, skip_bad: bool = False,
) -> tuple[np.ndarray, list[RecordingError]]:
    """The per-cell reader: any table the csv module reads, and the error naming the line
    and column for a row that is not one (cell count, a cell that is not a finite number;
    an empty temperature cell is "not recorded", NaN). With ``skip_bad`` such lines are left
    out and returned, unless they are more than :data:`MAX_BAD_FRACTION` of the lines."""
    reader = csv.reader(io.StringIO(text), delimiter=delim)
    if has_header:
        next(reader)
    rows: list[list[float]] = []
    bad: list[RecordingError] = []
    for line_no, row in enumerate(reader, start=first_line):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            rows.append(_row_values(p, line_no, row, header, wanted, idx))
        except RecordingError as exc:
            if DECIMAL_COMMA in exc.message:  # the whole table's, not one garbled line's
                raise
            if not skip_bad:
                raise RecordingError(exc.path, exc.line, exc.column,
                                     f"{exc.message} ({SKIP_HINT})") from None
            bad.append(exc)
    if not rows:
        raise RecordingError(p, first_line, None, "no data rows after the header")
    if len(bad) > MAX_BAD_FRACTION * (len(rows) + len(bad)):
        first = bad[0]
        raise RecordingError(
            p, first.line, first.column,
            f"{first.message}; {len(bad)} of {len(rows) + len(bad)} lines are not rows of the "
            f"table, more than the {MAX_BAD_FRACTION:.0%} --bad-lines skip leaves out: check "
            "--delimiter and --columns")
    return np.asarray(rows, float), bad


def _row_values(p: str, line_no: int, row: Sequence[str], header: Sequence[str],
                wanted: Sequence[str], idx: Sequence[int]) -> list[float]:
    if len(row) != len(header):
        raise RecordingError(p, line_no, None, f"has {len(row)} cells, header has {len(header)}")
    vals = []
    for r, i in zip(wanted, idx, strict=True):
        cell = row[i].strip()
        # An empty temperature cell is "not recorded" (recording format), not an error.
        empty_temp = r == "temp" and not cell
        vals.append(np.nan if empty_temp else _number(p, line_no, header[i], cell))
    return vals


def _check_distinct_columns(p: str, cmap: Mapping[str, str], wanted: Sequence[str]) -> None:
    """Each role read from its own column: ``--columns ax=2,…,temp=2`` would read an
    acceleration as the temperature (or one axis twice), and a model of it is nonsense."""
    seen: dict[str, str] = {}
    for role in wanted:
        name = cmap[role]
        if name in seen:
            raise RecordingError(
                p, None, None, f"--columns: {seen[name]} and {role} both name column "
                f"{name!r}: each of t, ax, ay, az, temp needs its own column (give --columns "
                f"{role}=NAME with the right column)")
        seen[name] = role


# Words in a time column's name that state its unit (split at non-letters and at
# camel-case humps: ``TimeUS``, ``t_ms``, ``time (ms)``, ``t[s]``).
TIME_UNIT_WORDS: dict[str, str] = {
    "s": "s", "sec": "s", "secs": "s", "second": "s", "seconds": "s",
    "ms": "ms", "msec": "ms", "millis": "ms", "millisecond": "ms", "milliseconds": "ms",
    "us": "us", "µs": "us", "usec": "us", "micros": "us", "microsecond": "us",
    "microseconds": "us"}


def time_unit_in_name(name: str) -> str | None:
    """The time unit a column's name states (:data:`TIME_UNIT_WORDS`), or None."""
    words = re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-zµ]+", name)
    units = {TIME_UNIT_WORDS[w.lower()] for w in words if w.lower() in TIME_UNIT_WORDS}
    return units.pop() if len(units) == 1 else None


def _check_time_unit_name(p: str, column: str, unit: str) -> None:
    """A time column named in one unit and read in another (``t_ms`` read as seconds) makes
    a 200-s warm-up 55 hours long: every rate, every 5-s capture and the model's rate term
    are then wrong, and nothing in the numbers shows it. Refused, naming the fix."""
    named = time_unit_in_name(column)
    if named is not None and named != unit:
        raise RecordingError(
            p, 1, column, f"the time column is named in {named} but read in {unit} "
            f"(--time-unit, default s): give --time-unit {named}, or --columns t=NAME for "
            f"the right column")


# A run of this many consecutive rows found again, identical in every value read, is a
# block written twice (a logger re-sending its buffer, two copies of a file joined): a
# sensor's noise never repeats 64 samples of 3 axes and a temperature (even rows that
# flicker between two codes repeat a given 64 with probability 2^-64 per pair). Only
# windows in which the rows change at least every other row count (a stuck sensor, or a
# quiet one between codes, repeats itself).
REPEAT_MIN_ROWS = 64


def _check_no_repeated_block(p: str, values: np.ndarray) -> None:
    """Refuse a table holding a block of rows twice (:data:`REPEAT_MIN_ROWS`); the message
    names both copies by data row (1 = the first data row) and their length."""
    found = repeated_block(values)
    if found is None:
        return
    first, again, length = found
    raise RecordingError(
        p, None, None, f"data rows {again + 1}..{again + length} repeat rows {first + 1}.."
        f"{first + length} value for value ({length} rows): a block written twice (a "
        f"logger re-sending its buffer, a file joined to a copy of itself), which a "
        f"calibration would count as more data: remove the repeated rows")


# An odd multiplier and its inverse modulo 2^64 (the windows' position weights).
_P = np.uint64(0xD6E8FEB86659FD93)
_P_INV = np.uint64(pow(0xD6E8FEB86659FD93, -1, 2**64))


def repeated_block(values: np.ndarray, window: int = REPEAT_MIN_ROWS
                   ) -> tuple[int, int, int] | None:
    """(first, again, length): rows ``again…`` repeat rows ``first…`` for ``length`` rows
    (the earliest repeat of at least ``window`` varying rows), or None.

    Each row's bits are mixed into one 64-bit hash, each window's hash is the sum of its
    rows' weighted by their place in it (a difference of one running sum: linear in the
    rows), and windows with equal hashes are compared value for value. About 5 arrays of
    8 bytes a row beside ``values``."""
    n = values.shape[0]
    if n < 2 * window:
        return None
    mult = np.uint64(0x9E3779B97F4A7C15)
    row_hash = np.zeros(n, np.uint64)
    for k in range(values.shape[1]):  # splitmix-style mixing of each cell into the row's
        row_hash ^= np.ascontiguousarray(values[:, k], dtype=np.float64).view(np.uint64)
        row_hash *= mult
        row_hash ^= row_hash >> np.uint64(31)
    m = n - window + 1
    change = np.concatenate([[0], np.cumsum(row_hash[1:] != row_hash[:-1])])
    varied = np.flatnonzero(change[window - 1:] - change[:m] >= window // 2)
    del change
    if varied.size < 2:
        return None
    # Σ_k row_hash[i+k]·P^-k (mod 2^64), from one running sum of row_hash[t]·P^-t: the
    # weights make a window's hash depend on the order of its rows
    running = np.full(n + 1, _P_INV, np.uint64)
    running[0] = running[1] = 1
    np.cumprod(running[1:], out=running[1:])
    running[1:] *= row_hash
    running[0] = 0
    np.cumsum(running, out=running)
    del row_hash
    p_pow = np.full(m, _P, np.uint64)
    p_pow[0] = 1
    np.cumprod(p_pow, out=p_pow)
    hv = ((running[window:] - running[:m]) * p_pow)[varied]
    del running, p_pow
    order = np.argsort(hv, kind="stable")
    same = np.flatnonzero(hv[order][1:] == hv[order][:-1])
    best = None
    for s in same:
        i, j = sorted((int(varied[order[s]]), int(varied[order[s + 1]])))
        if (best is None or j < best[1]) and np.array_equal(values[i:i + window],
                                                           values[j:j + window]):
            best = (i, j)
    if best is None:
        return None
    i, j = best
    span = min(n - j, j - i)
    differ = np.flatnonzero(~np.all(values[i:i + span] == values[j:j + span], axis=1))
    return i, j, int(differ[0]) if differ.size else span


def _bad_lines_note(bad: Sequence[RecordingError], n_rows: int, *, timed: bool) -> str:
    """What ``--bad-lines skip`` left out, line by line (the first few)."""
    shown = "; ".join(f"line {e.line}" + (f" column '{e.column}'" if e.column else "")
                      + f": {e.message}" for e in bad[:BAD_LINES_SHOWN])
    more = f"; and {len(bad) - BAD_LINES_SHOWN} more" if len(bad) > BAD_LINES_SHOWN else ""
    clock = ("" if timed else
             " (without a time column, t = i / rate counts the rows kept: a line that held "
             "samples shifts the later times by one period each)")
    return (f"{len(bad)} line(s) not rows of the table left out (--bad-lines skip), "
            f"{n_rows} rows kept{clock}: {shown}{more}")


def _check_units(p: str, u: TableUnits) -> None:
    if u.bad_lines not in BAD_LINES:
        raise RecordingError(p, None, None, f"--bad-lines is one of {', '.join(BAD_LINES)}, "
                             f"got {u.bad_lines!r}")
    if u.accel is None:
        raise RecordingError(p, None, None, "the acceleration unit is not guessed: give "
                             f"--accel-unit ({', '.join([*ACCEL_UNITS, 'counts'])})")
    if u.accel not in ACCEL_UNITS and u.accel != "counts":
        raise RecordingError(p, None, None, f"--accel-unit {u.accel!r}: expected one of "
                             f"{', '.join([*ACCEL_UNITS, 'counts'])}")
    if u.accel == "counts" and u.counts_per_g is None:
        raise RecordingError(p, None, None, "--accel-unit counts needs --counts-per-g "
                             "(the sensitivity, counts per g)")
    if u.temp not in TEMP_UNITS:
        raise RecordingError(p, None, None,
                             f"--temp-unit {u.temp!r}: expected one of {', '.join(TEMP_UNITS)}")
    if u.temp == "counts" and (u.temp_c_per_count is None or u.temp_offset_c is None):
        raise RecordingError(p, None, None, "--temp-unit counts needs --temp-c-per-count "
                             "and --temp-offset-c")
    if u.time not in TIME_UNITS:
        raise RecordingError(p, None, None,
                             f"--time-unit {u.time!r}: expected one of {', '.join(TIME_UNITS)}")
    if u.rate_hz is not None and not u.rate_hz > 0:
        raise RecordingError(p, None, None, f"--rate-hz must be > 0, got {u.rate_hz}")


def _to_g(acc: np.ndarray, u: TableUnits) -> tuple[np.ndarray, str]:
    if u.accel == "counts":
        scale = np.broadcast_to(np.asarray(u.counts_per_g, float), (3,))
        offset = np.broadcast_to(np.asarray(u.offset_counts, float), (3,))
        return (acc - offset) / scale, f"counts: (c − {_fmt3(offset)}) / {_fmt3(scale)} → g"
    assert u.accel is not None
    return acc * ACCEL_UNITS[u.accel], f"acceleration in {u.accel} → g"


def _to_c(temp: np.ndarray, u: TableUnits) -> tuple[np.ndarray, str]:
    if u.temp == "C":
        return temp, "temperature in °C → sensor_c"
    if u.temp == "F":
        return (temp - 32.0) * 5.0 / 9.0, "temperature in °F → sensor_c (°C)"
    if u.temp == "K":
        return temp - 273.15, "temperature in K → sensor_c (°C)"
    assert u.temp_c_per_count is not None and u.temp_offset_c is not None
    return (u.temp_offset_c + temp * u.temp_c_per_count,
            f"temperature counts → sensor_c = {u.temp_offset_c:g} + c × {u.temp_c_per_count:g}")


def _all_numbers(cells: Sequence[str]) -> bool:
    """A first row of numbers only is data, not a header."""
    try:
        for c in cells:
            float(c)
    except ValueError:
        return False
    return bool(cells)


def _leading_banner(lines: Sequence[str], delimiter: str | None) -> int:
    """How many leading lines are not rows of the table, 0 … :data:`BANNER_MAX_LINES`.

    A terminal logger (PuTTY: "=~=~=~ PuTTY log 2026.05.08 15:24:01 =~=~=~") writes a
    banner before the data, and a serial capture that starts mid-line begins with a row
    cut short. The table starts at the first line with more than one cell whose next
    :data:`BANNER_CONFIRM_LINES` non-blank lines have as many cells (its delimiter
    sniffed from it, as a header's is). A line before it is skipped only if it cannot be
    a header: blank, without any delimiter (a banner), or numbers only and fewer cells
    than the line after it (a row cut short). Any other line stops the search and
    nothing is skipped, so a table that does not line up is refused by the row checks
    with its line number, as before."""
    for start in range(min(BANNER_MAX_LINES, len(lines))):
        line = lines[start]
        delim = delimiter or _sniff(line)
        width = _cell_count(line, delim)
        # only the next few non-blank lines: the file may hold 100,000 rows
        following = (x for x in islice(lines, start + 1, None) if x.strip())
        after = [_cell_count(x, delim) for x in islice(following, BANNER_CONFIRM_LINES)]
        if width > 1 and all(n == width for n in after):
            return start
        if not line.strip() or not any(d in line for d in (delimiter or ",;\t")):
            continue  # blank, or a banner with no delimiter
        nxt = next((x for x in islice(lines, start + 1, None) if x.strip()), "")
        cells = next(csv.reader([line], delimiter=delim))
        if _all_numbers([c.strip() for c in cells]) and width < _cell_count(
                nxt, delimiter or _sniff(nxt)):
            continue  # a row cut short
        return 0
    return 0


def _cell_count(line: str, delimiter: str) -> int:
    return len(next(csv.reader([line], delimiter=delimiter), []))


def _sniff(header_line: str) -> str:
    counts = {d: header_line.count(d) for d in (",", ";", "\t")}
    best = max(counts, key=lambda d: counts[d])
    return best if counts[best] else ","

