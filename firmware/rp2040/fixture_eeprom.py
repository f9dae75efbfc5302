# Fixture EEPROM holding the sensor's serial (docs/sensor-bridge.md, "Identity").
#
# A 24AA02/24LC02-class I2C EEPROM (256 bytes, 8-byte pages, address 0x50) on
# the sensor's fixture cable: the serial lives with the sensor, not the bridge
# board, so swapping bridges keeps the binding. Layout: "SC1:" magic, then the
# serial in ASCII, NUL-terminated, at most 24 characters. Written with the
# bridge's SN command. Works with any object offering MicroPython's
# machine.I2C readfrom_mem / writeto_mem; ``sleep_ms`` waits out each page write.

MAGIC = b"SC1:"
MAX_SERIAL = 24
PAGE = 8
WRITE_CYCLE_MS = 5  # 24AA02 t_WC maximum


class FixtureEeprom:
    def __init__(self, i2c, addr=0x50, sleep_ms=None):
        self.i2c = i2c
        self.addr = addr
        self.sleep_ms = sleep_ms or (lambda ms: None)

    def read_serial(self):
        """The stored serial, or "" when blank (erased 0xFF), unformatted or not printable."""
        data = self.i2c.readfrom_mem(self.addr, 0, len(MAGIC) + MAX_SERIAL + 1)
        if data[:len(MAGIC)] != MAGIC:
            return ""
        body = data[len(MAGIC):]
        end = body.find(b"\x00")
        if end < 1:
            return ""
        for b in body[:end]:
            if b < 0x21 or b > 0x7E or b in b"$*,":
                return ""
        return body[:end].decode()

    def write_serial(self, serial):
        blob = MAGIC + serial.encode() + b"\x00"
        for start in range(0, len(blob), PAGE):
            self.i2c.writeto_mem(self.addr, start, blob[start:start + PAGE])
            self.sleep_ms(WRITE_CYCLE_MS)
