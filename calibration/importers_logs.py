"""Flight-controller logs with the IMU's own temperature: PX4 ULog and ArduPilot DataFlash.

* ``ulog`` -- PX4 ULog (read with ``pyulog``): topic ``sensor_accel`` (``x, y, z`` in
  m/s², ``temperature`` in °C, ``timestamp`` in µs), one instance (``multi_id``). These
  are the driver's output in the frame PX4's thermal compensation (``TC_A*``) works in,
  before the ``CAL_ACC*`` offsets and scales.
* ``dataflash`` -- ArduPilot DataFlash ``.bin`` (read with ``pymavlink``'s DFReader):
  message ``IMU`` (``AccX, AccY, AccZ`` in m/s², ``T`` in °C, ``TimeUS`` in µs), one
  instance (field ``I``, or the older message names ``IMU2``/``IMU3``). Older layouts
  are read too (:data:`DATAFLASH_TIME_FIELDS`, :data:`DATAFLASH_TEMP_FIELDS`): the
  temperature was ``Temp`` in ArduPilot 3.3-3.4 and 3DR Solo, and the time ``TimeMS``
  (ms) before 3.3 and in Solo; logs before 3.3 keep no IMU temperature. ArduPilot logs
  these *after* its own corrections (``INS_ACCOFFS``/``INS_ACCSCAL`` and, when
  ``INS_TCALn_ENABLE`` = 1, its temperature calibration); the notes say when the log's
  parameters show a temperature calibration already applied.

Both are time series (one orientation while the board warms, usually): the readers
return every sample; :mod:`calibration.importers_cli` writes them as rows.
"""

from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from calibration.errors import RecordingError
from calibration.firmware_flight import ardupilot_accel_reading
from calibration.importers import (
    NO_TEMP_CONSEQUENCE,
    STANDARD_GRAVITY_M_S2,
    RawImport,
    _check_monotonic,
    vet_die_temperature,
)

ULOG_TOPIC = "sensor_accel"
DATAFLASH_MESSAGE = "IMU"
# The IMU message's time field and its factor to µs, newest layout first: ``TimeUS``
# since ArduPilot 3.3; ``TimeMS`` before (ArduCopter 3.2, 3DR Solo's firmware).
DATAFLASH_TIME_FIELDS = (("TimeUS", 1.0), ("TimeMS", 1000.0))
# Its temperature field (°C): ``T`` since ArduPilot 3.5; ``Temp`` in 3.3-3.4 and Solo.
DATAFLASH_TEMP_FIELDS = ("T", "Temp")


def read_ulog(path: str | Path, *, instance: int = 0) -> RawImport:
    """PX4 ULog ``sensor_accel`` instance ``instance``: m/s² → g, µs → s, °C kept."""
    from pyulog import ULog  # a dependency of this reader only

    p = str(path)
    if not Path(p).is_file():
        raise RecordingError(p, None, None, "file not found")
    try:
        ulog = ULog(p, [ULOG_TOPIC], True)
    except Exception as exc:  # pyulog raises bare Exceptions/struct errors on bad input
        raise RecordingError(p, None, None, f"not a readable PX4 ULog ({_short(exc)})") from None
    found = {d.multi_id: d for d in ulog.data_list if d.name == ULOG_TOPIC}
    if not found:
        raise RecordingError(p, None, ULOG_TOPIC,
                             "no sensor_accel topic in this log: log it (SDLOG_PROFILE "
                             "'thermal calibration' or 'sensor comparison')")
    if instance not in found:
        raise RecordingError(p, None, ULOG_TOPIC, f"no instance {instance}; the log has "
                             f"{', '.join(str(i) for i in sorted(found))} (--instance N)")
    data = found[instance].data
    for name in ("timestamp", "x", "y", "z"):
        if name not in data:
            raise RecordingError(p, None, f"{ULOG_TOPIC}.{name}", "field missing")
    t_us = np.asarray(data["timestamp"], float)
    _check_monotonic(p, t_us, f"{ULOG_TOPIC}.timestamp", first_line=1)
    acc = np.column_stack([np.asarray(data[c], float) for c in "xyz"]) / STANDARD_GRAVITY_M_S2
    notes = [f"PX4 sensor_accel instance {instance}: m/s² / {STANDARD_GRAVITY_M_S2} → g"]
    others = sorted(set(found) - {instance})
    if others:
        notes.append(f"other sensor_accel instances not read: {', '.join(map(str, others))}")
    if "device_id" in data and len(data["device_id"]):
        dev = int(np.median(np.asarray(data["device_id"], float)))
        notes.append(f"device_id {dev} (PX4's TC_A*_ID for this accelerometer)")
    t_s = (t_us - t_us[0]) * 1e-6
    temp_c = None
    if "temperature" not in data:
        notes.append("no sensor_accel temperature field; temperature left empty: "
                     f"{NO_TEMP_CONSEQUENCE}")
    else:
        temp_c, why = vet_die_temperature(np.asarray(data["temperature"], float), t_s,
                                          "sensor_accel temperature")
        notes.append(why or "sensor_accel temperature → sensor_c (°C)")
    _dropouts(ulog, notes)
    return RawImport(p, "ulog", t_s, acc, init_rest_s=None, notes=notes,
                     temp_c=temp_c)


def _dropouts(ulog: Any, notes: list[str]) -> None:
    drops = getattr(ulog, "dropouts", [])
    if drops:
        total_ms = sum(int(getattr(d, "duration", 0)) for d in drops)
        notes.append(f"the logger dropped data {len(drops)} times ({total_ms} ms in all)")


def read_dataflash(path: str | Path, *, instance: int = 0) -> RawImport:
    """ArduPilot DataFlash ``IMU`` instance ``instance`` (0-based): m/s² → g, ``T`` °C."""
    from pymavlink import DFReader  # a dependency of this reader only

    p = str(path)
    if not Path(p).is_file():
        raise RecordingError(p, None, None, "file not found")
    _check_dataflash_head(p)
    chatter = _LineCounter()  # DFReader prints a line per byte it cannot read
    with contextlib.redirect_stderr(chatter), contextlib.redirect_stdout(chatter):
        raw = _read_dataflash(p, instance, DFReader)
    if chatter.lines:
        raw.notes.append(f"pymavlink's DFReader reported {chatter.lines} line(s) on bytes it "
                         f"could not read as messages (the first: {chatter.first!r}): a "
                         "corrupt or cut part of the log, left out")
    return raw


# Every ArduPilot DataFlash (.bin) message begins with these two bytes (HEAD_BYTE1 and
# HEAD_BYTE2, libraries/AP_Logger/LogStructure.h), the file's first message included.
DATAFLASH_HEAD = b"\xa3\x95"
DATAFLASH_HEAD_SHOWN = 16


def _check_dataflash_head(p: str) -> None:
    """Refuse a file that does not begin as a DataFlash log, naming what it begins with:
    DFReader would read such a file byte by byte, print a line for each (3.6 M lines for a
    3.6 MB CSV) and find no IMU message, which blames the instance."""
    with open(p, "rb") as f:
        head = f.read(DATAFLASH_HEAD_SHOWN)
    if head.startswith(DATAFLASH_HEAD):
        return
    if not head:
        raise RecordingError(p, None, None, "empty file: not an ArduPilot DataFlash log")
    text = all(32 <= b < 127 or b in (9, 10, 13) for b in head)
    what = (": text, not a binary log (an ArduPilot .log text log is not read; a table: "
            "--format csv)" if text else "")
    raise RecordingError(
        p, None, None, f"not an ArduPilot DataFlash .bin log: it begins "
        f"{head.decode('latin-1')!r}, not with a DataFlash message header (bytes A3 95)"
        f"{what}")


# The lines DFReader prints about bytes it cannot read as messages (pymavlink/DFReader.py).
DFREADER_SKIP_LINES = ("bad header", "unknown msg type", "Skipped", "bad msg")


class _LineCounter(io.TextIOBase):
    """A text sink that counts DFReader's lines about unreadable bytes
    (:data:`DFREADER_SKIP_LINES`), keeps the first, and drops everything else."""

    def __init__(self) -> None:
        self.lines = 0
        self.first = ""

    def write(self, text: str) -> int:
        for line in text.splitlines():
            if line.startswith(DFREADER_SKIP_LINES):
                self.lines += 1
                self.first = self.first or line
        return len(text)


def _read_dataflash(p: str, instance: int, DFReader: Any) -> RawImport:
    """:func:`read_dataflash` once the file is known to begin as a DataFlash log."""
    try:
        log = DFReader.DFReader_binary(p, zero_time_base=True)
    except Exception as exc:  # DFReader raises on truncated or foreign files
        raise RecordingError(p, None, None,
                             f"not a readable DataFlash log ({_short(exc)})") from None
    old_name = DATAFLASH_MESSAGE if instance == 0 else f"{DATAFLASH_MESSAGE}{instance + 1}"
    t_us: list[float] = []
    acc: list[tuple[float, float, float]] = []
    temp: list[float] = []
    has_t = True
    time_fields: set[str] = set()
    temp_fields: set[str] = set()
    tcal_enabled: set[str] = set()
    id_name = "INS_ACC_ID" if instance == 0 else f"INS_ACC{instance + 1}_ID"
    accel_id: int | None = None
    try:
        fast = dataflash_imu_columns(log, instance, old_name)
    except Exception:  # a format this does not foresee: the loop, DFReader's own reading
        fast = None
    # The IMU samples at once from the reader's own index (below); then the loop reads
    # the parameters only. Without it, the loop reads every IMU message too.
    wanted = ["PARM"] if fast is not None else [DATAFLASH_MESSAGE, old_name, "PARM"]
    while True:
        try:
            m = log.recv_match(type=wanted)
        except Exception as exc:
            raise RecordingError(p, None, None, f"unreadable message ({_short(exc)})") from None
        if m is None:
            break
        mtype = m.get_type()
        if mtype == "PARM":
            name = str(getattr(m, "Name", ""))
            if name == f"INS_TCAL{instance + 1}_ENABLE" and m.Value == 1:
                tcal_enabled.add(name)
            elif name == id_name and m.Value:
                accel_id = int(m.Value)
            continue
        if hasattr(m, "I"):  # ArduPilot >= 4.0: one IMU message, instance in field I
            if mtype != DATAFLASH_MESSAGE or int(m.I) != instance:
                continue
        elif mtype != old_name:  # older logs: IMU, IMU2, IMU3
            continue
        time_field, to_us, temp_field = dataflash_imu_fields(m.get_fieldnames())
        if time_field is None:
            raise RecordingError(p, None, mtype, "no time field (TimeUS or TimeMS) in this "
                                 "log's IMU messages: not an ArduPilot layout this reads")
        time_fields.add(time_field)
        t_us.append(float(getattr(m, time_field)) * to_us)
        acc.append((float(m.AccX), float(m.AccY), float(m.AccZ)))
        if temp_field is not None:
            temp_fields.add(temp_field)
            temp.append(float(getattr(m, temp_field)))
        else:
            has_t = False
            temp.append(math.nan)
    if fast is not None:
        t, acc_m_s2, temp_arr, has_t, fast_time, fast_temp = fast
        time_fields.update(fast_time)
        temp_fields.update(fast_temp)
    else:
        t, acc_m_s2, temp_arr = np.asarray(t_us), np.asarray(acc), np.asarray(temp)
    if not t.size:
        raise RecordingError(p, None, DATAFLASH_MESSAGE,
                             f"no IMU messages for instance {instance} (--instance N; "
                             "0 is the first IMU)")
    time_name = "/".join(sorted(time_fields, reverse=True)) or "TimeUS"
    _check_monotonic(p, t, f"IMU.{time_name}", first_line=1)
    notes = [f"ArduPilot IMU instance {instance}: m/s² / {STANDARD_GRAVITY_M_S2} → g "
             "(ArduPilot's corrected output: INS_ACCOFFS/INS_ACCSCAL applied)"]
    if "TimeMS" in time_fields:
        notes.append("IMU time read from TimeMS (whole milliseconds: a log from before "
                     "ArduPilot 3.3, or 3DR Solo)")
    if tcal_enabled:
        notes.append(f"{', '.join(sorted(tcal_enabled))} = 1 in this log: the readings "
                     "are already temperature-compensated by the autopilot")
    if accel_id is not None:
        notes.append(_driver_note(id_name, accel_id))
    t_s = (t - t[0]) * 1e-6
    temp_c: np.ndarray | None = None
    if not has_t:
        notes.append("no IMU T field (nor Temp: ArduPilot logs the IMU temperature from "
                     f"3.3 on); temperature left empty: {NO_TEMP_CONSEQUENCE}")
    else:
        name = "IMU " + "/".join(sorted(temp_fields, key=DATAFLASH_TEMP_FIELDS.index))
        temp_c, why = vet_die_temperature(temp_arr, t_s, name)
        notes.append(why or f"{name} → sensor_c (°C)")
    return RawImport(p, "dataflash", t_s, acc_m_s2 / STANDARD_GRAVITY_M_S2, init_rest_s=None,
                     notes=notes, temp_c=temp_c)


def _driver_note(id_name: str, accel_id: int) -> str:
    """What the log's accelerometer device id says about the temperature reading its
    ArduPilot driver hands ``INS_TCAL`` (:func:`calibration.firmware_flight.
    ardupilot_accel_reading`), and so which ``soakcal export --format ardupilot`` file."""
    reading, device = ardupilot_accel_reading(accel_id)
    head = f"{id_name} {accel_id} is {device}"
    if reading is None:
        return (f"{head}: soakcal does not know whether its ArduPilot driver filters the "
                "temperature; read the driver before choosing `soakcal export --format "
                "ardupilot --temperature-reading filtered|per-sample`")
    return f"{head}: export its ArduPilot file with --temperature-reading {reading}"


# struct character → numpy type, for the numeric fields DFReader's formats use
_STRUCT_TO_NUMPY = {"b": "i1", "B": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4",
                    "q": "<i8", "Q": "<u8", "e": "<f2", "f": "<f4", "d": "<f8"}
# DataFlash format characters whose value DFReader gives as a number (pymavlink's
# FORMAT_TO_STRUCT): 'M' (a flight mode), 'a' (an int16 array) and strings are not read here
_NUMERIC_FORMATS = "bBhHiIqQgfdcCeEL"
# the message types DFReader's recv_match visits besides the ones asked for (not strict)
_DFREADER_ALWAYS = ("MODE", "MSG", "PARM", "STAT", "ORGN", "VER")
_GATHER_ROWS = 1 << 18  # messages gathered at a time: a bounded index array


def dataflash_imu_fields(columns: Any) -> tuple[str | None, float, str | None]:
    """(time field, its factor to µs, temperature field or ``None``) of an IMU message
    with these column names, by :data:`DATAFLASH_TIME_FIELDS` and
    :data:`DATAFLASH_TEMP_FIELDS`; the time field is ``None`` when it has neither."""
    names = set(columns)
    time_field, to_us = next(((f, k) for f, k in DATAFLASH_TIME_FIELDS if f in names),
                             (None, 1.0))
    temp_field = next((f for f in DATAFLASH_TEMP_FIELDS if f in names), None)
    return time_field, to_us, temp_field


def dataflash_imu_columns(
    log: Any, instance: int, old_name: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool, set[str], set[str]] | None:
    """(time in µs, AccX/Y/Z, temperature, whether every message has one, the time and
    temperature field names read) of the ``IMU`` messages that the
    message loop of :func:`read_dataflash` takes, read at once from DFReader's own index
    (``offsets``: where each message of each type starts) and formats; ``None`` when that
    is not sure to give the same numbers, and the loop reads them.

    Why (issue 20): the loop builds a Python message object per sample, 28 µs each, more
    than a minute for a 40-minute log at 1 kHz. Here each field is gathered from the
    file's bytes with numpy and converted as DFReader's message converts it (the field's
    Python type, then its format's multiplier, divided by 1/m when m < 1). In file order,
    the messages of ``IMU`` with field ``I`` equal to ``instance``, or, in logs whose
    ``IMU`` has no ``I``, every message named ``old_name``.
    """
    offsets = getattr(log, "offsets", None)
    formats = getattr(log, "formats", None)
    names = getattr(log, "name_to_id", None)
    data = getattr(log, "data_map", None)
    if offsets is None or formats is None or names is None or data is None:
        return None
    data_len = int(log.data_len)
    visited = dict.fromkeys((DATAFLASH_MESSAGE, old_name, *_DFREADER_ALWAYS))
    for name in visited:  # the loop ends at a message cut off by the end of the file
        mtype = names.get(name)
        if mtype is not None and len(offsets[mtype]) and (
                offsets[mtype][-1] + formats[mtype].len > data_len):
            return None
    buf = np.frombuffer(data, np.uint8)
    picks = []
    for name in dict.fromkeys((DATAFLASH_MESSAGE, old_name)):
        mtype = names.get(name)
        if mtype is None or not len(offsets[mtype]):
            continue
        fmt = formats[mtype]
        has_i = "I" in fmt.colhash
        if (has_i and name != DATAFLASH_MESSAGE) or (not has_i and name != old_name):
            continue  # the loop's rule: I names the instance; without it, the old name does
        time_field, to_us, temp_field = dataflash_imu_fields(fmt.colhash)
        if time_field is None:
            return None  # the loop says why
        fields = [time_field, "AccX", "AccY", "AccZ", *(["I"] if has_i else []),
                  *([temp_field] if temp_field else [])]
        starts = np.asarray(offsets[mtype], np.int64)
        cols = _gather_fields(buf, starts, fmt, fields)
        if cols is None:
            return None
        keep = cols["I"] == instance if has_i else np.ones(starts.size, bool)
        temp = cols[temp_field][keep] if temp_field else np.full(int(keep.sum()), np.nan)
        picks.append((starts[keep], cols[time_field][keep] * to_us, cols, keep, temp,
                      time_field, temp_field))
    picks = [pk for pk in picks if pk[0].size]
    if not picks:
        return np.zeros(0), np.zeros((0, 3)), np.zeros(0), True, set(), set()
    order = np.argsort(np.concatenate([pk[0] for pk in picks]), kind="stable")
    t_us = np.concatenate([pk[1] for pk in picks])[order]
    acc = np.column_stack([np.concatenate([pk[2][c][pk[3]] for pk in picks])[order]
                           for c in ("AccX", "AccY", "AccZ")])
    temp = np.concatenate([pk[4] for pk in picks])[order]
    return (t_us, acc, temp, all(pk[6] for pk in picks), {pk[5] for pk in picks},
            {pk[6] for pk in picks if pk[6]})


def _gather_fields(
    buf: np.ndarray, starts: np.ndarray, fmt: Any, fields: list[str]
) -> dict[str, np.ndarray] | None:
    """The named fields of the messages at ``starts`` as float64 arrays, each value what
    ``float(getattr(message, field))`` gives in DFReader, or ``None`` for a field this
    does not convert (a string, an array, a flight mode)."""
    import struct

    tokens = [fmt.msg_struct[1:][i] for i in range(len(fmt.msg_struct) - 1)]
    if fmt.msg_struct[:1] != "<" or any(not c.isalpha() for c in tokens) or len(tokens) != len(
            fmt.msg_fmts):
        return None  # a string or array field ("64s"): offsets not one character each
    sizes = [struct.calcsize("<" + c) for c in tokens]
    where = np.cumsum([3, *sizes[:-1]])  # each field's byte offset in the message
    out: dict[str, np.ndarray] = {}
    for name in fields:
        i = fmt.colhash[name]
        char = fmt.msg_fmts[i]
        if char not in _NUMERIC_FORMATS or fmt.format[i] != char:
            return None
        dtype = np.dtype(_STRUCT_TO_NUMPY[tokens[i]])
        values = np.empty(starts.size, np.float64)
        span = np.arange(sizes[i])
        for lo in range(0, starts.size, _GATHER_ROWS):
            at = starts[lo:lo + _GATHER_ROWS, None] + (int(where[i]) + span)
            values[lo:lo + _GATHER_ROWS] = buf[at].view(dtype).ravel()
        mult = fmt.msg_mults[i]
        if mult is not None:  # as DFMessage.__getattr__: divide by 1/m for m < 1
            if 0.0 < mult < 1.0:
                values /= 1 / mult
            else:
                values *= mult
        out[name] = values
    return out


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:120]
