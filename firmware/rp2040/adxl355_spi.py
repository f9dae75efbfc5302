# ADXL355 over SPI, register level (Analog Devices ADXL354/ADXL355 data sheet,
# register map and SPI protocol). Written against an abstract SPI device: any
# object with ``transfer(tx: bytes) -> bytes`` that holds chip select low for the
# whole transfer. main.py wraps machine.SPI + a CS pin; the tests wrap the
# register-level simulator (simulators/adxl355_regs.py). MicroPython-safe.

DEVID_AD = 0x00  # reads 0xAD
DEVID_MST = 0x01  # reads 0x1D
PARTID = 0x02  # reads 0xED
REVID = 0x03
STATUS = 0x04  # bit 0 DATA_RDY
TEMP2 = 0x06  # bits 3:0 = temperature bits 11:8
TEMP1 = 0x07  # temperature bits 7:0
XDATA3 = 0x08  # X, Y, Z: 3 registers each, 20-bit two's complement, left-justified
FILTER = 0x28  # bits 3:0 ODR_LPF: ODR = 4000 Hz / 2**code
RANGE = 0x2C  # bits 1:0: 01 = +-2 g, 10 = +-4 g, 11 = +-8 g
POWER_CTL = 0x2D  # bit 0 STANDBY (1 after reset)
RESET = 0x2F  # write 0x52 for a software reset

EXPECTED_IDS = (0xAD, 0x1D, 0xED)
RANGE_CODES = {2: 0x01, 4: 0x02, 8: 0x03}
ODR_MAX_HZ = 4000.0


def odr_code(odr_hz):
    """Closest ODR_LPF code 0..10 for a requested rate (4000 Hz .. 3.906 Hz)."""
    best = 0
    for code in range(11):
        if abs(ODR_MAX_HZ / (1 << code) - odr_hz) < abs(ODR_MAX_HZ / (1 << best) - odr_hz):
            best = code
    return best


def twos20(d3, d2, d1):
    """Three data registers -> signed 20-bit count (data sheet: D[19:12], D[11:4], D[3:0]<<4)."""
    v = (d3 << 12) | (d2 << 4) | (d1 >> 4)
    return v - (1 << 20) if v & 0x80000 else v


class ADXL355:
    def __init__(self, spi):
        self.spi = spi

    def read(self, reg, n=1):
        # Command byte: address in bits 7:1, R/W in bit 0 (1 = read); the address
        # auto-increments over a multi-byte read.
        rx = self.spi.transfer(bytes([(reg << 1) | 1]) + bytes(n))
        return rx[1:]

    def write(self, reg, value):
        self.spi.transfer(bytes([reg << 1, value & 0xFF]))

    def ids(self):
        """(DEVID_AD, DEVID_MST, PARTID, REVID) in one burst."""
        b = self.read(DEVID_AD, 4)
        return b[0], b[1], b[2], b[3]

    def configure(self, range_g, odr_hz):
        """Standby, set range and ODR, measure. Returns (range_g, actual_odr_hz)."""
        code = odr_code(odr_hz)
        self.write(POWER_CTL, 0x01)  # range and filter are written in standby (data sheet)
        self.write(RANGE, (self.read(RANGE)[0] & 0xFC) | RANGE_CODES[range_g])
        self.write(FILTER, (self.read(FILTER)[0] & 0xF0) | code)
        self.write(POWER_CTL, 0x00)  # measurement mode, temperature on, DRDY on
        return range_g, ODR_MAX_HZ / (1 << code)

    def data_ready(self):
        return bool(self.read(STATUS)[0] & 0x01)

    def sample(self):
        """One burst TEMP2..ZDATA1 (11 bytes): ((x, y, z) counts, 12-bit temperature code)."""
        b = self.read(TEMP2, 11)
        temp = ((b[0] & 0x0F) << 8) | b[1]
        return (twos20(b[2], b[3], b[4]), twos20(b[5], b[6], b[7]),
                twos20(b[8], b[9], b[10])), temp
