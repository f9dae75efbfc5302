"""The C-speed path of the table readers: a plain delimited body parsed by numpy at once.

Why (issue 20, "Speed"): a flight controller's thermal-calibration log is a board warmed
for 30–60 min with the accelerometer logged at 0.4–1 kHz, millions of rows. The per-cell
reader (csv module, one Python ``float`` per cell, a list per row) took 74 s and 1.9 GB
for 2.4 M rows. Here the body is parsed by numpy's C reader (``np.loadtxt``: the same
correctly rounded decimal → binary conversion as ``float``, ``PyOS_string_to_double``),
the same numbers bit for bit.

This path only answers when it is sure to agree with the per-cell reader: plain
printable ASCII text (no quotes, no control characters but the tab), every data line
with as many cells as the header, no blank line inside the body, every wanted cell a
finite number. Anything else returns ``None``, and the caller's per-cell reader reads
the file and gives the same result, or the error naming the line and column.
"""

from __future__ import annotations

import operator
from collections.abc import Iterator, Sequence

import numpy as np

# Printable ASCII, the tab and the line feed: what a plain table holds. A vertical tab, a
# form feed or a file separator (str.splitlines cuts lines there, the csv module does not),
# a NUL (the csv module refuses it) or a carriage return are left to the per-cell reader.
_PLAIN_BYTES = bytes(range(0x20, 0x7F)) + b"\t\n"
# Lines handed to numpy at a time: a bounded copy of the text, not one of all of it.
BLOCK_CHARS = 1 << 20


class _Decline(Exception):
    """The body is not plain: the per-cell reader decides."""


def is_plain(text: str) -> bool:
    """Printable ASCII, tabs and line feeds only, and no quote character."""
    if not text.isascii() or '"' in text:
        return False
    return not any(text[i:i + BLOCK_CHARS].encode("ascii").translate(None, _PLAIN_BYTES)
                   for i in range(0, len(text), BLOCK_CHARS))


def head_lines(text: str, max_lines: int, confirm_lines: int) -> tuple[str, list[str]]:
    """The leading part of ``text`` cut at a line end, and its lines.

    Its lines are the first lines of ``text.splitlines()``, enough for a search of the
    first ``max_lines`` lines that looks ``confirm_lines`` non-blank lines ahead (or all
    of them, for a shorter text), without splitting a file of millions of rows.
    """
    want = max_lines + confirm_lines + 1
    while True:
        end = 0
        for _ in range(want):
            end = text.find("\n", end) + 1
            if end == 0:
                return text, text.splitlines()
        lines = text[:end].splitlines()
        if sum(1 for x in lines[max_lines:] if x.strip()) > confirm_lines:
            return text[:end], lines
        want *= 2


def parse_plain_rows(
    text: str, start: int, delimiter: str, n_cells: int, usecols: Sequence[int],
    *, empty_is_nan: int | None = None,
) -> np.ndarray | None:
    """The ``usecols`` cells of the data rows ``text[start:]`` as a (rows, len(usecols))
    float array, or ``None`` when the per-cell reader must decide (see the module
    docstring). ``text`` must be :func:`is_plain`; trailing blank lines are ignored, as
    the per-cell reader skips them.

    ``empty_is_nan`` (an index into ``usecols``): that column's empty cells are NaN ("not
    recorded", as a temperature logged at a lower rate than the acceleration leaves
    them), as the per-cell reader reads them. Then the rows' empty cells are written
    ``nan`` before numpy reads them, provided the text has no letter n anywhere (so no
    ``nan`` or ``inf`` of its own, which the per-cell reader refuses), and a NaN in
    any other column (an empty cell there) leaves the table to the per-cell reader."""
    end = len(text)
    while end > start and text[end - 1] == "\n":  # not text.rstrip(): a copy of it all
        end -= 1
    if n_cells < 2 or end <= start or len(delimiter) != 1:
        return None
    fill = empty_is_nan is not None and _has_empty_cell(text, start, end, delimiter)
    if fill and (text.find("n", start, end) >= 0 or text.find("N", start, end) >= 0):
        return None
    try:
        values = np.loadtxt(
            _checked_lines(text, start, end, delimiter, n_cells - 1, fill=fill),
            delimiter=delimiter, comments=None, quotechar=None, usecols=list(usecols),
            dtype=float, ndmin=2)
    except (_Decline, ValueError):
        return None
    finite = np.isfinite(values)
    if fill:
        finite[:, empty_is_nan] |= np.isnan(values[:, empty_is_nan])
    if not finite.all():
        return None  # "nan", "inf", "1e999": the per-cell reader names line and column
    return values


def _has_empty_cell(text: str, start: int, end: int, delimiter: str) -> bool:
    d = delimiter
    return (text.startswith(d, start) or text.endswith(d, start, end)
            or any(text.find(p, start, end) >= 0 for p in (d + d, "\n" + d, d + "\n")))


def _fill_empty(block: str, delimiter: str) -> str:
    """Each empty cell of the rows of ``block`` written ``nan``."""
    d = delimiter
    b = ("\n" + block + "\n").replace("\n" + d, "\nnan" + d).replace(d + "\n", d + "nan\n")
    while d + d in b:
        b = b.replace(d + d, d + "nan" + d)
    return b[1:-1]


def _checked_lines(
    text: str, start: int, end: int, delimiter: str, n_delimiters: int, *, fill: bool
) -> Iterator[str]:
    """The lines of ``text[start:end]``, a block at a time (empty cells written ``nan``
    when ``fill``); raises :class:`_Decline` on a blank line or a line with another
    number of cells (the per-cell reader skips the first and refuses the second, naming
    its line)."""
    count = operator.methodcaller("count", delimiter)
    pos = start
    while pos < end:
        cut = text.find("\n", min(pos + BLOCK_CHARS, end), end)
        cut = end if cut < 0 else cut
        block = text[pos:cut]
        lines = block.split("\n")
        if not all(lines) or set(map(count, lines)) != {n_delimiters}:
            raise _Decline
        yield from (_fill_empty(block, delimiter).split("\n") if fill else lines)
        pos = cut + 1
