# soakcal sensor bridge, MicroPython entry point for a Raspberry Pi Pico (RP2040).
# Copy bridge_proto.py, adxl355_spi.py, fixture_eeprom.py, bridge_app.py and this
# file to the board (docs/sensor-bridge.md, "Firmware": `mpremote cp ... :`).
#
# Wiring (EVAL-ADXL355-PMDZ, 3.3 V): SPI0 SCK GP18, MOSI GP19, MISO GP16, CS GP17;
# fixture EEPROM (optional) on I2C0 SDA GP4, SCL GP5. The host talks over the
# Pico's native USB CDC serial port (/dev/ttyACM0); the baud rate is ignored.
# Pull GP15 to ground at boot for the plain streaming mode (x_g,y_g,z_g,temp_c
# lines, channel 0 only) instead of framed commands.
# Updating a running board (docs/sensor-bridge.md, "Updating a running board"): the framed
# command REPL (`$REPL*6D39`) leaves the command loop; GP14 pulled to ground at boot skips
# the bridge altogether. Either way the MicroPython REPL answers mpremote again.
#
# Several sensors on one bridge (docs/sensor-bridge.md, "Channels"): one chip select
# per sensor, channel i on CS_PINS[i], all on SPI0; channel i's fixture EEPROM at I2C
# address 0x50 + i (a 24xx02 with its A2..A0 pins strapped to the channel).

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


CS_PINS = (17,)  # one chip select per channel: e.g. (17, 20, 21, 22) for four sensors


def open_eeprom(i2c, present, channel):
    addr = 0x50 + channel
    if addr not in present:
        return None
    return fixture_eeprom.FixtureEeprom(i2c, addr, time.sleep_ms)


def main():
    if Pin(14, Pin.IN, Pin.PULL_UP).value() == 0:
        return  # boot-pin escape: no bridge, the REPL stays free for mpremote
    # ADXL355: SPI mode 0 (CPOL = 0, CPHA = 0), up to 10 MHz; 5 MHz leaves margin on a cable.
    spi = SPI(0, baudrate=5000000, polarity=0, phase=0, sck=Pin(18), mosi=Pin(19),
              miso=Pin(16))
    # every chip select high before any transfer: one sensor on the bus at a time
    selects = [Pin(p, Pin.OUT, value=1) for p in CS_PINS]
    i2c = I2C(0, sda=Pin(4), scl=Pin(5), freq=100000)
    present = i2c.scan()
    uid = board_uid()
    bridges = {}
    for channel in range(len(selects)):
        sensor = adxl355_spi.ADXL355(PinSPI(spi, selects[channel]))
        sensor.write(adxl355_spi.RESET, 0x52)
        time.sleep_ms(10)
        bridges[channel] = bridge_app.Bridge(sensor, uid, open_eeprom(i2c, present, channel),
                                             time.sleep_us)
    bridge = bridge_app.MuxBridge(bridges)
    out = sys.stdout.buffer if hasattr(sys.stdout, "buffer") else sys.stdout
    stream_mode = Pin(15, Pin.IN, Pin.PULL_UP).value() == 0
    if stream_mode:
        while True:
            out.write(bridges[0].stream_line())
    inp = sys.stdin.buffer if hasattr(sys.stdin, "buffer") else sys.stdin
    poll = select.poll()
    poll.register(inp, select.POLLIN)

    def read_byte():
        poll.poll()
        return inp.read(1)

    micropython.kbd_intr(-1)  # 0x03 on the line is data, not Ctrl-C
    try:
        bridge_app.serve(bridge, read_byte, out.write)  # returns on the REPL command
    finally:
        micropython.kbd_intr(3)  # Ctrl-C interrupts again: mpremote can take the REPL


main()
