"""Flight-controller logs with the IMU's own temperature: PX4 ULog and ArduPilot DataFlash.

* ``ulog`` -- PX4 ULog (read with ``pyulog``): topic ``sensor_accel`` (``x, y, z`` in
  m/s², ``temperature`` in °C, ``timestamp`` in µs), one instance (``multi_id``). These
  are the driver's output in the frame PX4's thermal compensation (``TC_A*``) works in,
  before the ``CAL_ACC*`` offsets and scales.
* ``dataflash`` -- ArduPilot DataFlash ``.bin`` (read with ``pymavlink``'s DFReader):
  message ``IMU`` (``AccX, AccY, AccZ`` in m/s², ``T`` in °C, ``TimeUS`` in µs), one
  instance (field ``I``, or the older message names ``IMU2``/``IMU3``). ArduPilot logs
  these *after* its own corrections (``INS_ACCOFFS``/``INS_ACCSCAL`` and, when
  ``INS_TCALn_ENABLE`` = 1, its temperature calibration); the notes say when the log's
  parameters show a temperature calibration already applied.

Both are time series (one orientation while the board warms, usually): the readers
return every sample; :mod:`calibration.importers_cli` writes them as rows.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from calibration.errors import RecordingError
from calibration.importers import (
    NO_TEMP_CONSEQUENCE,
    STANDARD_GRAVITY_M_S2,
    RawImport,
    _check_monotonic,
    vet_die_temperature,
)

ULOG_TOPIC = "sensor_accel"
DATAFLASH_MESSAGE = "IMU"


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
    tcal_enabled: set[str] = set()
    while True:
        try:
            m = log.recv_match(type=[DATAFLASH_MESSAGE, old_name, "PARM"])
        except Exception as exc:
            raise RecordingError(p, None, None, f"unreadable message ({_short(exc)})") from None
        if m is None:
            break
        mtype = m.get_type()
        if mtype == "PARM":
            name = str(getattr(m, "Name", ""))
            if name == f"INS_TCAL{instance + 1}_ENABLE" and m.Value == 1:
                tcal_enabled.add(name)
            continue
        if hasattr(m, "I"):  # ArduPilot >= 4.0: one IMU message, instance in field I
            if mtype != DATAFLASH_MESSAGE or int(m.I) != instance:
                continue
        elif mtype != old_name:  # older logs: IMU, IMU2, IMU3
            continue
        t_us.append(float(m.TimeUS))
        acc.append((float(m.AccX), float(m.AccY), float(m.AccZ)))
        if hasattr(m, "T"):
            temp.append(float(m.T))
        else:
            has_t = False
            temp.append(math.nan)
    if not t_us:
        raise RecordingError(p, None, DATAFLASH_MESSAGE,
                             f"no IMU messages for instance {instance} (--instance N; "
                             "0 is the first IMU)")
    t = np.asarray(t_us)
    _check_monotonic(p, t, "IMU.TimeUS", first_line=1)
    notes = [f"ArduPilot IMU instance {instance}: m/s² / {STANDARD_GRAVITY_M_S2} → g "
             "(ArduPilot's corrected output: INS_ACCOFFS/INS_ACCSCAL applied)"]
    if tcal_enabled:
        notes.append(f"{', '.join(sorted(tcal_enabled))} = 1 in this log: the readings "
                     "are already temperature-compensated by the autopilot")
    t_s = (t - t[0]) * 1e-6
    temp_c: np.ndarray | None = None
    if not has_t:
        notes.append("no IMU T field (log older than ArduPilot 4.1?); temperature left "
                     f"empty: {NO_TEMP_CONSEQUENCE}")
    else:
        temp_c, why = vet_die_temperature(np.asarray(temp), t_s, "IMU T")
        notes.append(why or "IMU T → sensor_c (°C)")
    return RawImport(p, "dataflash", t_s,
                     np.asarray(acc) / STANDARD_GRAVITY_M_S2, init_rest_s=None, notes=notes,
                     temp_c=temp_c)


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:120]
