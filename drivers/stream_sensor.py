"""Accelerometer on a plain text stream: one line per sample, averaged on the host.

What common hobby firmware prints (and ``firmware/rp2040`` in stream mode):
``x,y,z,t`` per line, commas, semicolons or blanks between the four numbers,
optionally labelled (``X: 0.012 Y=-0.004 z:0.998 T:24.9``). Column order and
acceleration units come from the rig config (:class:`drivers.sensor_config.StreamFormat`);
temperature is in °C. There is no framing, so every line is checked: any byte
outside printable ASCII, or a line without exactly four numbers, is dropped
and counted; too many such lines in one capture is a :class:`ProtocolError`.
A stream cannot be configured or identified (docs/sensor-bridge.md, "Plain
streaming mode").
"""

from __future__ import annotations

import re

import numpy as np
import serial

from drivers.clock import Clock
from drivers.faults import (
    ConnectionLost,
    DeviceTimeout,
    ProtocolError,
    ValueOutOfRange,
)
from drivers.protocols import Acquisition, SensorIdentity
from drivers.sensor_bridge import SerialLine
from drivers.sensor_config import StreamFormat

STANDARD_GRAVITY_M_S2 = 9.80665  # converts m/s² lines to g (the fit's unit)
G_PER_UNIT = {"g": 1.0, "mg": 1e-3, "m/s2": 1.0 / STANDARD_GRAVITY_M_S2}
_SEPARATORS = re.compile(rb"[,;\s]+")
_LABEL = re.compile(rb"^[A-Za-z_]+[:=]")


def parse_stream_line(line: bytes, fmt: StreamFormat) -> tuple[np.ndarray, float] | None:
    """One line → (acceleration g (3,), temperature °C), or ``None`` if it is not a sample."""
    raw = line.rstrip(b"\r\n")
    if any(not (0x20 <= b <= 0x7E or b == 0x09) for b in raw):
        return None
    tokens = [t for t in _SEPARATORS.split(raw.strip()) if t]
    values: list[float] = []
    for tok in tokens:
        tok = _LABEL.sub(b"", tok)
        if not tok:
            continue  # "X: 0.01": the label was its own token
        try:
            values.append(float(tok))
        except ValueError:
            return None
    if len(values) != 4 or not all(np.isfinite(values)):
        return None
    by_name = dict(zip(fmt.columns, values, strict=True))
    scale = G_PER_UNIT[fmt.units]
    return np.array([by_name["x"], by_name["y"], by_name["z"]]) * scale, by_name["t"]


class StreamingAccelerometer:
    """:class:`drivers.protocols.Accelerometer` over a free-running text stream."""

    def __init__(self, url: str, clock: Clock, *, fmt: StreamFormat | None = None,
                 baudrate: int = 115200, timeout_s: float = 2.0, attempts: int = 2,
                 device: str = "sensor") -> None:
        self.url = url
        self.clock = clock
        self.fmt = fmt or StreamFormat()
        self.baudrate = baudrate
        self.timeout_s = timeout_s  # wall time per line
        self.attempts = attempts
        self.device = device
        self._line = SerialLine(url, clock, baudrate=baudrate, timeout_s=timeout_s,
                                attempts=attempts, device=device, name=f"stream {url}")

    async def identify(self) -> SensorIdentity:
        """A plain stream reports nothing: the serial is the operator's word (binding ``any``)."""
        return SensorIdentity(model="unknown", serial="", firmware="", protocol="stream")

    async def configure(self, range_g: float, odr_hz: float) -> None:
        """Nothing to send; refuse a campaign range the streaming firmware is not set to."""
        if float(range_g) != self.fmt.range_g:
            raise ValueOutOfRange(self.device, f"the stream runs at ±{self.fmt.range_g:g} g "
                                               f"(stream.range_g) but ±{range_g:g} g was asked")

    async def acquire(self, n_samples: int) -> Acquisition:
        if n_samples < 1:
            raise ValueOutOfRange(self.device, f"n_samples must be ≥ 1, got {n_samples}")
        t0 = self.clock.now()
        g, temps_c = await self._capture(n_samples)
        sd = g.std(axis=0, ddof=1) if len(g) > 1 else np.zeros(3)
        return Acquisition(
            mean_g=tuple(float(x) for x in g.mean(axis=0)),  # type: ignore[arg-type]
            sd_g=tuple(float(x) for x in sd),  # type: ignore[arg-type]
            n=len(g),
            sensor_c=float(temps_c.mean()),
            sensor_c_span=float(temps_c.max() - temps_c.min()),
            saturated=bool(np.any(np.abs(g) >= self.fmt.range_g)),
            duration_s=self.clock.now() - t0,
        )

    async def close(self) -> None:
        await self._line.close()

    async def _capture(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        return await self._line.call(self._capture_blocking, n)

    def _capture_blocking(self, port: serial.SerialBase, n: int) -> tuple[np.ndarray, np.ndarray]:
        # Lines buffered before this call belong to an earlier orientation: drop them,
        # then drop the first line read (it may start mid-line).
        max_bad = 10 + n // 4  # a banner or a noise burst is dropped; a wrong format is not
        g = np.empty((n, 3))
        temps = np.empty(n)
        try:
            port.reset_input_buffer()
            port.timeout = self.timeout_s
            self._read_line(port)
            got = bad = 0
            while got < n:
                sample = parse_stream_line(self._read_line(port), self.fmt)
                if sample is None:
                    bad += 1
                    if bad > max_bad:
                        raise ProtocolError(self.device, f"{bad} lines that are not "
                                                         f"'x,y,z,t' samples in one capture")
                    continue
                g[got], temps[got] = sample
                got += 1
        except (serial.SerialException, OSError) as exc:
            raise ConnectionLost(self.device, f"{self.url}: {exc}") from exc
        return g, temps

    def _read_line(self, port: serial.SerialBase) -> bytes:
        line = port.read_until(b"\n")
        if not line.endswith(b"\n"):
            raise DeviceTimeout(self.device, f"no line from the stream within "
                                             f"{self.timeout_s:.1f} s")
        return line
