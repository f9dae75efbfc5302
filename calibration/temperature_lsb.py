"""A temperature channel's LSB, declared by the recording: ``sensor_lsb_c``, ``chamber_lsb_c``.

Why (issue 22): a channel quantised to q whose own noise is far below q (a 0.1 °C chamber
display, the ADXL355's ~0.11 °C code, a 0.0625 °C part read as it is) does not dither, and
every reading of a settled plateau carries that plateau's rounding error, within ±q/2. The
diagnosis must know q to allow for it. The recording shows q only when a plateau moves by a
code (calibration.discrepancy.plateau_noise.temperature_grid); a channel whose codes are the
setpoints alone does not, nor one whose die lingers at a code's edge. A lab knows its
channel's LSB from the datasheet or the display; this optional column says it.

Format (docs/recording.md, project additions): ``<channel>_lsb_c`` for ``sensor_c`` or
``chamber_c``, °C, in (0, 10], the same value on every row once used. Recordings without
it read as before.
"""

from __future__ import annotations

import numpy as np

from calibration.errors import RecordingError
from calibration.recording import Recording, optional_number_column

LSB_COLUMNS = {"sensor_c": "sensor_lsb_c", "chamber_c": "chamber_lsb_c"}
MAX_LSB_C = 10.0  # a coarser "LSB" is not a temperature channel's resolution


def declared_lsb_c(rec: Recording, channel: str) -> float | None:
    """The LSB (°C) the recording declares for ``channel``, or None when it declares none.

    Raises :class:`RecordingError` (file, line, column) for a cell that is not a number in
    (0, :data:`MAX_LSB_C`], an empty cell while others are filled, or two values (one
    channel has one LSB).
    """
    name = LSB_COLUMNS.get(channel)
    if name is None:
        return None
    values = optional_number_column(rec, name, "°C")
    if values is None or not np.isfinite(values).any():
        return None
    bad = np.flatnonzero(~np.isfinite(values) | (values <= 0) | (values > MAX_LSB_C))
    if bad.size:
        i = int(bad[0])
        what = "empty" if not np.isfinite(values[i]) else f"{values[i]:g}"
        raise RecordingError(rec.path, i + 2, name,
                             f"{what}: the channel's LSB must be a number of °C in "
                             f"(0, {MAX_LSB_C:g}] on every row once the column is used")
    other = np.flatnonzero(values != values[0])
    if other.size:
        i = int(other[0])
        raise RecordingError(rec.path, i + 2, name,
                             f"{values[i]:g} after {values[0]:g}: one channel has one LSB")
    return float(values[0])


