# soakcal sensor bridge, MicroPython entry point for a Raspberry Pi Pico (RP2040).
# Copy bridge_proto.py, adxl355_spi.py, fixture_eeprom.py, bridge_app.py and this
# file to the board (docs/sensor-bridge.md, "Firmware": `mpremote cp ... :`).
#
# Wiring (EVAL-ADXL355-PMDZ, 3.3 V): SPI0 SCK GP18, MOSI GP19, MISO GP16, CS GP17;
# fixture EEPROM (optional) on I2C0 SDA GP4, SCL GP5. The host talks over the
# Pico's native USB CDC serial port (/dev/ttyACM0); the baud rate is ignored.
# Pull GP15 to ground at boot for the plain streaming mode (x_g,y_g,z_g,temp_c
# lines) instead of framed commands.

import select
import sys
import time

import adxl355_spi
import bridge_app
import fixture_eeprom
import machine
import micropython
from machine import I2C, SPI, Pin


class PinSPI:
    """machine.SPI + chip-select pin as the abstract ``transfer(tx) -> rx`` device."""

    def __init__(self, spi, cs):
        self.spi = spi
        self.cs = cs

    def transfer(self, tx):
        rx = bytearray(len(tx))
        self.cs(0)
        try:
            self.spi.write_readinto(tx, rx)
        finally:
            self.cs(1)
        return bytes(rx)


def board_uid():
    return "".join(f"{b:02X}" for b in machine.unique_id())


def open_eeprom():
    i2c = I2C(0, sda=Pin(4), scl=Pin(5), freq=100000)
    if 0x50 not in i2c.scan():
        return None
    return fixture_eeprom.FixtureEeprom(i2c, 0x50, time.sleep_ms)


def main():
    cs = Pin(17, Pin.OUT, value=1)
    # ADXL355: SPI mode 0 (CPOL = 0, CPHA = 0), up to 10 MHz; 5 MHz leaves margin on a cable.
    spi = SPI(0, baudrate=5000000, polarity=0, phase=0, sck=Pin(18), mosi=Pin(19),
              miso=Pin(16))
    sensor = adxl355_spi.ADXL355(PinSPI(spi, cs))
    sensor.write(adxl355_spi.RESET, 0x52)
    time.sleep_ms(10)
    bridge = bridge_app.Bridge(sensor, board_uid(), open_eeprom(), time.sleep_us)
    out = sys.stdout.buffer if hasattr(sys.stdout, "buffer") else sys.stdout
    stream_mode = Pin(15, Pin.IN, Pin.PULL_UP).value() == 0
    if stream_mode:
        while True:
            out.write(bridge.stream_line())
    micropython.kbd_intr(-1)  # 0x03 on the line is data, not Ctrl-C
    inp = sys.stdin.buffer if hasattr(sys.stdin, "buffer") else sys.stdin
    poll = select.poll()
    poll.register(inp, select.POLLIN)
    line = b""
    while True:
        poll.poll()
        ch = inp.read(1)
        if not ch:
            continue
        line += ch
        if ch == b"\n":
            for reply in bridge.handle_line(line):
                out.write(reply)
            line = b""
        elif len(line) > 200:  # no command is this long: resynchronise on the next LF
            line = b""


main()
