# soakcal sensor bridge application: framed commands in, ADXL355 samples out.
#
# Protocol v2 (docs/sensor-bridge.md): ID, CFG, AVG, RAW, SN; replies in the
# framing the command came in (v2 CRC-16, or v1 XOR for hosts not yet updated).
# MuxBridge serves several ADXL355 on one SPI bus (one chip select each) behind the
# channel address "@<ch>" (docs/sensor-bridge.md, "Channels"); unaddressed commands are
# channel 0's, answered exactly as a one-sensor bridge does. Its group capture
# "AVG,<n>,@<ch>,@<ch>,..." averages n samples on every listed channel at once (each chip
# read in turn within each sample period) and answers one line per channel, then END.
# Replies are produced one line at a time (generators) and written as they come
# (serve_line): a RAW capture of 100000 samples never holds more than one line, so the
# heap a reply needs does not grow with n (a Pico has ~190 kB free).
# Averages are computed in exact integer arithmetic: the RP2040 port of
# MicroPython has single-precision floats only, which would round a mean of
# 256000 counts to 1/64 count; integers are exact and identical under CPython.
# MicroPython-safe: no typing, no math.isqrt, no int.bit_length; syntax of MicroPython
# MIN_MICROPYTHON or newer (checked with that version's mpy-cross in tests/firmware).

import adxl355_spi as adx
import bridge_proto as proto

# 2.1: channel addressing (MuxBridge); 2.2: group capture; 2.3: RAW streamed line by line,
# REPL command (leave the command loop so a running board can be updated)
FIRMWARE = "soakcal-fw-2.3"
MIN_MICROPYTHON = "1.20.0"  # oldest MicroPython whose compiler accepts every module here
MODEL = "ADXL355"
MAX_SAMPLES = 100000
LSB_PER_G = {2: 256000, 4: 128000, 8: 64000}
COUNT_MAX = (1 << 19) - 1
POLL_US = 100  # DATA_RDY polling period
MAX_CHANNEL = 99  # "@0".."@99": two decimal digits on the wire
NOT_READY = ["ERR", 5, "sensor not ready (no DATA_RDY)"]


class SensorStalled(Exception):
    pass


def fixed(num, den, places):
    """num / den rounded half away from zero to ``places`` decimals, as text (exact)."""
    scale = 10 ** places
    q = (abs(num) * scale * 2 + den) // (2 * den)
    sign = "-" if (num < 0 and q) else ""
    if places == 0:
        return sign + str(q)
    frac = str(q % scale)
    return sign + str(q // scale) + "." + "0" * (places - len(frac)) + frac


def isqrt(v):
    """Floor square root of a non-negative integer (Newton)."""
    if v <= 0:
        return 0
    x = v
    y = (x + 1) // 2
    while y < x:
        x = y
        y = (x + v // x) // 2
    return x


def temp_c_text(code):
    """12-bit temperature code -> degC text: 25 + (code - 1885) / (-9.05), 2 decimals."""
    return fixed(211125 - 100 * code, 905, 2)


class Averager:
    """Exact integer sums of one channel's capture -> its ``AVG`` reply fields.

    One place for the AVG arithmetic, whether a channel is captured alone or in a group.
    """

    def __init__(self, saturation_limit):
        self.limit = saturation_limit
        self.n = 0
        self.s = [0, 0, 0]
        self.ss = [0, 0, 0]
        self.t_sum = 0
        self.t_min = 4095
        self.t_max = 0
        self.sat = 0

    def add(self, xyz, t):
        self.n += 1
        for k in range(3):
            c = xyz[k]
            self.s[k] += c
            self.ss[k] += c * c
            if c >= self.limit or -c >= self.limit:
                self.sat = 1
        self.t_sum += t
        self.t_min = min(self.t_min, t)
        self.t_max = max(self.t_max, t)

    def reply(self):
        n, s, ss = self.n, self.s, self.ss
        means = [fixed(s[k], n, 3) for k in range(3)]
        sds = []
        for k in range(3):
            if n < 2:
                sds.append("0.000")
                continue
            # sample variance (ddof = 1) in counts^2 x 1e6, square-rooted to milli-counts
            var_micro = (n * ss[k] - s[k] * s[k]) * 1000000 // (n * (n - 1))
            sds.append(fixed(isqrt(var_micro), 1000, 3))
        return ["AVG", n] + means + sds + [fixed(self.t_sum, n, 2), self.t_min, self.t_max,
                                           self.sat]


class Bridge:
    """Command handler; ``sensor`` is an adxl355_spi.ADXL355, ``eeprom`` may be None.

    ``sleep_us`` is the only way this code waits (time.sleep_us on the board, a
    no-op or a virtual clock in the tests).
    """

    def __init__(self, sensor, board_uid, eeprom=None, sleep_us=None):
        self.sensor = sensor
        self.board_uid = board_uid
        self.eeprom = eeprom
        self.sleep_us = sleep_us or (lambda us: None)
        self.range_g = 2
        self.odr_hz = 62.5
        self.range_g, self.odr_hz = sensor.configure(self.range_g, self.odr_hz)

    # --- sample source --------------------------------------------------------------
    def next_sample(self):
        """Wait for DATA_RDY (up to 4 sample periods), then read one sample."""
        polls = int(4 * 1000000 / self.odr_hz / POLL_US) + 10
        for _ in range(polls):
            if self.sensor.data_ready():
                return self.sensor.sample()
            self.sleep_us(POLL_US)
        raise SensorStalled()

    # --- commands -------------------------------------------------------------------
    def handle_line(self, line):
        """One received line -> list of reply frames (bytes); for tests and short replies."""
        return list(self.frames(line))

    def serve_line(self, line, write):
        """Answer one received line, each reply frame passed to ``write`` as it is made."""
        for frame in self.frames(line):
            write(frame)

    def frames(self, line):
        """Reply frames (bytes) for one received line, one at a time."""
        parsed = proto.unframe(line)
        if parsed is None:
            yield proto.frame(["ERR", 2, "bad frame or checksum"])
            return
        fields, v1 = parsed
        for r in self.answer(fields, v1):
            yield proto.frame(r, v1)

    def answer(self, fields, v1=False):
        """Reply field lists for one command, one at a time; a stalled sensor ends them with
        ERR 5 (after the R lines already sent, in a RAW capture: the host drops the capture).
        """
        try:
            yield from self.replies(fields, v1)
        except SensorStalled:
            yield NOT_READY

    def eeprom_serial(self):
        return self.eeprom.read_serial() if self.eeprom is not None else ""

    def replies(self, fields, v1=False):
        """Reply field lists for one command (an iterable: RAW's lines are made as read)."""
        cmd = fields[0]
        if cmd == "ID" and len(fields) == 1:
            reply = ["ID", MODEL, self.eeprom_serial(), FIRMWARE]
            if not v1:
                ids = self.sensor.ids()
                reply.append(self.board_uid)
                reply.extend([f"{v:02X}" for v in ids])
            return [reply]
        if cmd == "CFG" and len(fields) == 3:
            return [self._cfg(fields[1], fields[2])]
        if cmd in ("AVG", "RAW") and len(fields) == 2:
            n = int(fields[1]) if fields[1].isdigit() else 0
            if not 1 <= n <= MAX_SAMPLES:
                return [["ERR", 3, "n must be 1.." + str(MAX_SAMPLES)]]
            return self._avg(n) if cmd == "AVG" else self._raw(n)
        if cmd == "SN" and len(fields) == 2:
            if self.eeprom is None:
                return [["ERR", 4, "no fixture EEPROM"]]
            if not 1 <= len(fields[1]) <= 24 or " " in fields[1]:
                return [["ERR", 3, "serial must be 1..24 characters without blanks"]]
            self.eeprom.write_serial(fields[1])
            return [["OK", "SN", self.eeprom.read_serial()]]
        return [["ERR", 1, "unknown command " + cmd]]

    def _cfg(self, range_text, odr_text):
        try:
            range_g = int(float(range_text))
            odr_hz = float(odr_text)
        except ValueError:
            return ["ERR", 3, "bad range or ODR"]
        if range_g not in LSB_PER_G or float(range_text) != range_g or \
                not 3.9 <= odr_hz <= adx.ODR_MAX_HZ:
            return ["ERR", 3, "range must be 2 or 4 or 8 g and ODR 3.9..4000 Hz"]
        self.range_g, self.odr_hz = self.sensor.configure(range_g, odr_hz)
        return ["OK", "CFG", str(self.range_g), f"{self.odr_hz:g}"]

    def _saturation_limit(self):
        return min(self.range_g * LSB_PER_G[self.range_g], COUNT_MAX)

    def _avg(self, n):
        acc = Averager(self._saturation_limit())
        for _ in range(n):
            xyz, t = self.next_sample()
            acc.add(xyz, t)
        return [acc.reply()]

    def _raw(self, n):
        """``R`` lines made one per sample as it is read, then ``END``: nothing is kept."""
        for i in range(n):
            xyz, t = self.next_sample()
            yield ["R", i] + [f"{c & 0xFFFFF:05X}" for c in xyz] + [t]
        yield ["END", n]

    # --- plain streaming mode ---------------------------------------------------------
    def stream_line(self):
        """One plain text line per sample: ``x_g,y_g,z_g,temp_c`` (no framing, no checksum)."""
        xyz, t = self.next_sample()
        lsb = LSB_PER_G[self.range_g]
        return (",".join([fixed(c, lsb, 6) for c in xyz]) + "," + temp_c_text(t)
                + "\r\n").encode()


class MuxBridge:
    """Several sensors behind one port: ``bridges`` maps a channel to its :class:`Bridge`.

    ``@<ch>,<command>`` goes to that channel's Bridge (its own sensor, chip select,
    range, ODR and fixture EEPROM) and every reply line carries ``@<ch>`` back, so the
    host can never take one channel's data for another's. An unaddressed command is
    channel 0's and is answered unaddressed, byte for byte as a one-sensor bridge;
    ``CHANNELS`` lists the channels and their fixture serials. One command at a time:
    the channels share the SPI bus and the serial line. The group capture
    ``AVG,<n>,@<ch>,...`` (:meth:`group_avg`) reads the listed channels in one capture.
    """

    def __init__(self, bridges):
        self.bridges = bridges
        self.leave = False  # set by REPL: serve() returns to the MicroPython REPL

    def handle_line(self, line):
        """One received line -> list of reply frames (bytes); for tests and short replies."""
        return list(self.frames(line))

    def serve_line(self, line, write):
        """Answer one received line, each reply frame passed to ``write`` as it is made."""
        for frame in self.frames(line):
            write(frame)

    def frames(self, line):
        """Reply frames (bytes) for one received line, one at a time."""
        parsed = proto.unframe(line)
        if parsed is None:
            yield proto.frame(["ERR", 2, "bad frame or checksum"])
            return
        fields, v1 = parsed
        head = fields[0]
        address = []
        channel = 0
        if head.startswith("@"):
            channel = channel_number(head)
            if channel is None or len(fields) < 2:
                yield proto.frame(["ERR", 3, "bad channel address " + head], v1)
                return
            address = [head]
            fields = fields[1:]
        elif fields == ["CHANNELS"]:
            yield proto.frame(self.channels_reply(), v1)
            return
        elif fields == ["REPL"]:
            # Leave the command loop for the MicroPython REPL (Ctrl-C is data while the loop
            # runs, so mpremote cannot interrupt it): how a running board is updated.
            self.leave = True
            yield proto.frame(["OK", "REPL"], v1)
            return
        elif head == "AVG" and len(fields) > 2:
            for r in self.group_avg(fields):
                yield proto.frame(r, v1)
            return
        bridge = self.bridges.get(channel)
        if bridge is None:
            replies = [["ERR", 7, "no sensor on channel " + str(channel)]]
        else:
            replies = bridge.answer(fields, v1)
        for r in replies:
            yield proto.frame(address + r, v1)

    def channels_reply(self):
        out = ["CHANNELS", len(self.bridges)]
        for ch in sorted(self.bridges):
            out.append(ch)
            out.append(self.bridges[ch].eeprom_serial())
        return out

    def group_avg(self, fields):
        """``AVG,<n>,@<ch>,...`` -> one ``@<ch>,AVG,...`` (or ``@<ch>,ERR,...``) line per
        listed channel, in the command's order, then ``END,AVG,<lines>``.

        Every sample period reads each chip in turn (its chip select, its DATA_RDY), so the
        samples of one period are simultaneous to within the SPI transfers and the whole
        group costs one capture's time, not one per channel. A channel that stalls gets its
        own ERR 5 line and the others go on; a bad n or channel list is one unaddressed
        ERR 3 for the whole command.
        """
        n = int(fields[1]) if fields[1].isdigit() else 0
        if not 1 <= n <= MAX_SAMPLES:
            return [["ERR", 3, "n must be 1.." + str(MAX_SAMPLES)]]
        channels = []
        for head in fields[2:]:
            ch = channel_number(head)
            if ch is None or ch in channels:
                return [["ERR", 3, "bad or repeated channel address " + head]]
            channels.append(ch)
        replies = {}
        active = []
        for ch in channels:
            bridge = self.bridges.get(ch)
            if bridge is None:
                replies[ch] = ["ERR", 7, "no sensor on channel " + str(ch)]
            else:
                active.append((ch, bridge, Averager(bridge._saturation_limit())))
        for _ in range(n):
            for item in list(active):
                ch, bridge, acc = item
                try:
                    xyz, t = bridge.next_sample()
                except SensorStalled:
                    replies[ch] = NOT_READY
                    active.remove(item)
                    continue
                acc.add(xyz, t)
        for ch, _bridge, acc in active:
            replies[ch] = acc.reply()
        out = [["@" + str(ch)] + replies[ch] for ch in channels]
        out.append(["END", "AVG", len(channels)])
        return out


def channel_number(head):
    """``"@<ch>"`` -> ch, or None unless decimal 0..MAX_CHANNEL without leading zeros."""
    digits = head[1:] if head.startswith("@") else ""
    if not digits.isdigit() or str(int(digits)) != digits or int(digits) > MAX_CHANNEL:
        return None
    return int(digits)


MAX_LINE = 200  # no command is this long: a longer line is dropped (resynchronise on LF)


def serve(bridge, read_byte, write):
    """The command loop: bytes in (``read_byte()`` -> one byte, b"" if none), replies out.

    Returns once ``bridge.leave`` is set (the ``REPL`` command), after its reply is
    written; main.py then gives the console back to the MicroPython REPL. Bytes that are no
    command (mpremote's Ctrl-C / Ctrl-A while the loop runs) are dropped at the next "$",
    which only ever starts a frame; a line that is no frame is answered ERR 2 at its LF.
    """
    line = b""
    while not bridge.leave:
        ch = read_byte()
        if not ch:
            continue
        if ch == b"$":
            line = b""  # "$" only ever starts a frame: drop whatever came before it
        line += ch
        if ch == b"\n":
            bridge.serve_line(line, write)
            line = b""
        elif len(line) > MAX_LINE:
            line = b""
