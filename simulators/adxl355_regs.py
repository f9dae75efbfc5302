"""Register-level ADXL355 behind an SPI transfer: what the bridge firmware talks to in tests.

Per the Analog Devices ADXL354/ADXL355 data sheet: id registers DEVID_AD 0x00
= 0xAD, DEVID_MST 0x01 = 0x1D, PARTID 0x02 = 0xED, REVID 0x03; STATUS 0x04 bit
0 DATA_RDY; TEMP2/TEMP1 0x06/0x07 (12-bit code, 1885 LSB at 25 °C, −9.05
LSB/°C); XDATA3..ZDATA1 0x08..0x10 (20-bit two's complement, left-justified in
three bytes); FILTER 0x28; RANGE 0x2C (bits 1:0, reset 0x81 = ±2 g); POWER_CTL
0x2D (bit 0 STANDBY, set after reset; bit 1 TEMP_OFF); RESET 0x2F (0x52). The
SPI command byte is ``address << 1 | R/W`` (1 = read); a multi-byte read
auto-increments the address.

Model: while measuring, each STATUS read that finds the previous sample
consumed converts a new one (``accel_g()`` and ``die_c()`` at that moment) and
sets DATA_RDY; reading the data registers clears it. Writes to FILTER and
RANGE outside standby are ignored, stricter than the part, so firmware that
forgets to enter standby first is caught by the tests.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from drivers import adxl355

ADXL355_IDS = (adxl355.DEVID_AD, adxl355.DEVID_MST, adxl355.PARTID, adxl355.REVID_SIM)
STATUS, TEMP2, XDATA3, ZDATA1 = 0x04, 0x06, 0x08, 0x10
FILTER, RANGE, POWER_CTL, RESET = 0x28, 0x2C, 0x2D, 0x2F
_RANGE_G = {1: 2.0, 2: 4.0, 3: 8.0}
_READ_ONLY = range(0x00, 0x12)


class ADXL355Registers:
    """An SPI slave: :meth:`transfer` takes the bytes clocked out, returns the bytes clocked in."""

    def __init__(self, accel_g: Callable[[], Sequence[float]], die_c: Callable[[], float],
                 *, rng: np.random.Generator | None = None, noise_g: float = 0.0,
                 ids: tuple[int, int, int, int] = ADXL355_IDS) -> None:
        self.accel_g = accel_g
        self.die_c = die_c
        self.rng = rng or np.random.default_rng(0)
        self.noise_g = noise_g  # white noise per axis per sample, g rms
        self.ids = ids
        self.regs = bytearray(0x40)
        self.conversions = 0
        self._fresh = False
        self.reset()

    def reset(self) -> None:
        self.regs[:] = bytes(len(self.regs))
        self.regs[0:4] = bytes(self.ids)
        self.regs[RANGE] = 0x81
        self.regs[POWER_CTL] = 0x01
        self._fresh = False

    @property
    def standby(self) -> bool:
        return bool(self.regs[POWER_CTL] & 0x01)

    @property
    def range_g(self) -> float:
        return _RANGE_G.get(self.regs[RANGE] & 0x03, 2.0)

    @property
    def odr_hz(self) -> float:
        return 4000.0 / (1 << min(self.regs[FILTER] & 0x0F, 10))

    def transfer(self, tx: bytes) -> bytes:
        if not tx:
            return b""
        addr, read = tx[0] >> 1, tx[0] & 0x01
        if not read:
            for i, value in enumerate(tx[1:]):
                self._write(addr + i, value)
            return bytes(len(tx))
        out = bytearray([0])
        for i in range(len(tx) - 1):
            out.append(self._read(addr + i))
        if addr <= ZDATA1 and addr + len(tx) - 2 >= XDATA3:
            self.regs[STATUS] &= 0xFE  # data read: DATA_RDY clears
            self._fresh = False
        return bytes(out)

    def _read(self, reg: int) -> int:
        if reg == STATUS and not self.standby and not self._fresh:
            self._convert()
        return self.regs[reg] if reg < len(self.regs) else 0

    def _write(self, reg: int, value: int) -> None:
        if reg in _READ_ONLY or reg >= len(self.regs):
            return
        if reg == RESET:
            if value == 0x52:
                self.reset()
            return
        if reg in (FILTER, RANGE) and not self.standby:
            return
        self.regs[reg] = value & 0xFF

    def _convert(self) -> None:
        g = np.asarray(self.accel_g(), dtype=float)
        if self.noise_g:
            g = g + self.rng.normal(0.0, self.noise_g, 3)
        counts = adxl355.g_to_counts(g, self.range_g)
        for axis, c in enumerate(counts):
            word = adxl355.counts_to_20bit(int(c))
            base = XDATA3 + 3 * axis
            self.regs[base:base + 3] = bytes([(word >> 12) & 0xFF, (word >> 4) & 0xFF,
                                              (word & 0x0F) << 4])
        if not self.regs[POWER_CTL] & 0x02:  # TEMP_OFF clear: temperature converts too
            code = int(adxl355.temp_c_to_raw(self.die_c()))
            self.regs[TEMP2], self.regs[TEMP2 + 1] = (code >> 8) & 0x0F, code & 0xFF
        self.regs[STATUS] |= 0x01
        self._fresh = True
        self.conversions += 1
