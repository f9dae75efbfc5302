"""Tiny PX4 ULog and ArduPilot DataFlash files built byte by byte for the importer tests.

Written from the published file formats (PX4 "ULog File Format"; ArduPilot DataFlash:
``FMT`` messages describing each message type, every message framed by 0xA3 0x95 and
its type id), not from any recorded log: the tests need no binary blob from outside.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

ULOG_MAGIC = b"ULog\x01\x12\x35"


def _ulog_msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write_ulog(
    path: Path,
    t_us: np.ndarray,
    acc_ms2: np.ndarray,
    temp_c: np.ndarray | None,
    *,
    device_id: int = 1310988,
    instances: int = 1,
) -> Path:
    """A ULog with topic ``sensor_accel`` (timestamp, device_id, x, y, z[, temperature]).

    ``instances`` > 1 logs the same samples again as multi_id 1.. with x + 1 m/s² per
    instance, so a test can tell the instances apart.
    """
    fields = "uint64_t timestamp;uint32_t device_id;float x;float y;float z;"
    if temp_c is not None:
        fields += "float temperature;"
    out = bytearray(ULOG_MAGIC + b"\x01" + struct.pack("<Q", int(t_us[0])))
    out += _ulog_msg(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    out += _ulog_msg(b"F", f"sensor_accel:{fields}".encode())
    for multi_id in range(instances):
        out += _ulog_msg(b"A", struct.pack("<BH", multi_id, multi_id) + b"sensor_accel")
    for k in range(len(t_us)):
        for multi_id in range(instances):
            x, y, z = acc_ms2[k]
            body = struct.pack("<HQIfff", multi_id, int(t_us[k]), device_id,
                               x + multi_id, y, z)
            if temp_c is not None:
                body += struct.pack("<f", temp_c[k])
            out += _ulog_msg(b"D", body)
    path.write_bytes(bytes(out))
    return path


DF_HEAD = b"\xa3\x95"
FMT_ID, IMU_ID, PARM_ID = 128, 130, 131


def _df_fmt(type_id: int, name: str, fmt: str, columns: str, length: int) -> bytes:
    return DF_HEAD + struct.pack(
        "<BBB4s16s64s", FMT_ID, type_id, length, name.encode(), fmt.encode(), columns.encode())


def write_dataflash(
    path: Path,
    t_us: np.ndarray,
    acc_ms2: np.ndarray,
    temp_c: np.ndarray | None,
    *,
    instances: int = 1,
    params: dict[str, float] | None = None,
) -> Path:
    """A DataFlash .bin with ``FMT``, optional ``PARM`` and ``IMU`` messages.

    With a temperature: ArduPilot 4.x's IMU layout (``TimeUS,I,Gyr*,Acc*,EG,EA,T,GH,AH,
    GHz,AHz``); without: the same less ``T`` (a log from before the field existed).
    Instance ``i`` > 0 reads x + i m/s².
    """
    head = "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,"
    if temp_c is not None:
        imu_fmt, imu_cols = "QBffffffIIfBBHH", head + "T,GH,AH,GHz,AHz"
    else:
        imu_fmt, imu_cols = "QBffffffIIBBHH", head + "GH,AH,GHz,AHz"
    body_fmt = "<" + imu_fmt
    imu_len = 3 + struct.calcsize(body_fmt)
    out = bytearray()
    out += _df_fmt(FMT_ID, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", 89)
    out += _df_fmt(IMU_ID, "IMU", imu_fmt, imu_cols, imu_len)
    out += _df_fmt(PARM_ID, "PARM", "QNf", "TimeUS,Name,Value", 3 + struct.calcsize("<Q16sf"))
    for name, value in (params or {}).items():
        out += DF_HEAD + struct.pack("<BQ16sf", PARM_ID, int(t_us[0]), name.encode(), value)
    for k in range(len(t_us)):
        for inst in range(instances):
            x, y, z = acc_ms2[k]
            vals: list[float | int] = [int(t_us[k]), inst, 0.0, 0.0, 0.0, x + inst, y, z, 0, 0]
            if temp_c is not None:
                vals.append(float(temp_c[k]))
            vals += [1, 1, 1000, 1000]
            out += DF_HEAD + struct.pack("<B", IMU_ID) + struct.pack(body_fmt, *vals)
    path.write_bytes(bytes(out))
    return path


# Older ArduPilot IMU layouts (FMT format, columns), as their FMT messages read in real
# logs: ArduCopter 3.2 (time in ms, no temperature), 3DR Solo (time in ms, ``Temp``),
# ArduCopter 3.3 (time in µs, ``Temp``). Each logs IMU2 for the second sensor.
LEGACY_IMU_LAYOUTS = {
    "copter-3.2": ("Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "solo": ("IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp"),
    "copter-3.3": ("QffffffIIfBB",
                   "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp,GyHlt,AcHlt"),
}


def write_dataflash_legacy(
    path: Path, t_us: np.ndarray, acc_ms2: np.ndarray, temp_c: np.ndarray | None, *,
    layout: str,
) -> Path:
    """A DataFlash .bin in one of :data:`LEGACY_IMU_LAYOUTS`, messages ``IMU`` and ``IMU2``
    (x + 1 m/s²; 1 °C warmer). ``temp_c`` is ignored by a layout with no temperature.
    Times in ms are ``t_us`` // 1000."""
    imu_fmt, imu_cols = LEGACY_IMU_LAYOUTS[layout]
    body_fmt = "<" + imu_fmt
    imu_len = 3 + struct.calcsize(body_fmt)
    in_ms = imu_cols.startswith("TimeMS")
    out = bytearray()
    out += _df_fmt(FMT_ID, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", 89)
    out += _df_fmt(IMU_ID, "IMU", imu_fmt, imu_cols, imu_len)
    out += _df_fmt(IMU_ID + 5, "IMU2", imu_fmt, imu_cols, imu_len)
    for k in range(len(t_us)):
        for type_id, inst in ((IMU_ID, 0), (IMU_ID + 5, 1)):
            x, y, z = acc_ms2[k]
            t = int(t_us[k]) // 1000 if in_ms else int(t_us[k])
            vals: list[float | int] = [t, 0.0, 0.0, 0.0, x + inst, y, z]
            if "ErrG" in imu_cols:
                vals += [0, 0, float(temp_c[k]) + inst if temp_c is not None else 0.0]
            if "GyHlt" in imu_cols:
                vals += [1, 1]
            out += DF_HEAD + struct.pack("<B", type_id) + struct.pack(body_fmt, *vals)
    path.write_bytes(bytes(out))
    return path


def warmup_samples(n: int = 400, rate_hz: float = 50.0, seed: int = 0):
    """A board at rest, z up, warming 30 → 40 °C; z bias drifts +2 mg/°C. (t_us, m/s², °C)."""
    rng = np.random.default_rng(seed)
    t_us = 1_000_000 + np.arange(n) * (1e6 / rate_hz)
    temp = np.linspace(30.0, 40.0, n)
    g = 9.80665
    acc = np.column_stack([
        np.full(n, 0.01 * g), np.full(n, -0.02 * g), (1.0 + 0.002 * (temp - 30.0)) * g])
    acc = acc + rng.normal(0, 1e-4 * g, acc.shape)
    return t_us, acc.astype(np.float32).astype(float), temp.astype(np.float32).astype(float)


def flight_samples(seconds: float = 120.0, rate_hz: float = 50.0, *, vibration_g: float = 0.04,
                   still_s: float = 0.0, seed: int = 0):
    """A multicopter's IMU in flight (t_us, m/s²): gravity on -z (ArduPilot's body frame,
    z down) swaying by a few degrees with the attitude, plus ``vibration_g`` rms per axis
    of motor vibration (a 2014 ArduCopter flight read 41-128 mg rms per axis); the first
    ``still_s`` seconds on the ground, disarmed (1 mg of noise)."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds * rate_hz))
    t = np.arange(n) / rate_hz
    roll = np.radians(4.0) * np.sin(2 * np.pi * t / 7.0)
    pitch = np.radians(6.0) * np.sin(2 * np.pi * t / 11.0 + 1.0)
    g = 9.80665
    acc = g * np.column_stack([np.sin(pitch), -np.sin(roll) * np.cos(pitch),
                               -np.cos(roll) * np.cos(pitch)])
    noise = np.full(n, vibration_g)
    ground = t < still_s
    acc[ground] = [0.0, 0.0, -g]
    noise[ground] = 1e-3
    acc = acc + rng.normal(0.0, 1.0, acc.shape) * noise[:, None] * g
    return 1_000_000 + np.round(t * 1e6), acc.astype(np.float32).astype(float)
