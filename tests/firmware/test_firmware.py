"""Reference bridge firmware under CPython: register-level ADXL355, a pty, the real drivers.

The firmware source in firmware/rp2040 runs unchanged here (the conftest puts
it on sys.path as the board's flat modules); only main.py, which needs
``machine``, is compiled and scanned but not run.
"""

from __future__ import annotations

import ast
import random
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import adxl355_spi
import bridge_app
import bridge_proto
import fixture_eeprom
import numpy as np
import pytest
from pty_device import PtyDevice

from drivers import adxl355
from drivers.bridge_protocol import encode_frame, parse_frame
from drivers.clock import VirtualClock
from drivers.faults import ConfigurationFault, ExceptionReply, ProtocolError, ValueOutOfRange
from drivers.sensor_bridge import SerialAccelerometer
from drivers.sensor_config import StreamFormat
from drivers.stream_sensor import StreamingAccelerometer
from service.engine.identity import SensorMismatch, SerialBinding, verify_sensor
from simulators.adxl355_regs import ADXL355Registers

FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware" / "rp2040"
UID = "E6614104035F2B2F"
TRUE_G = (0.0123, -0.0456, 0.9876)


class MemI2C:
    """machine.I2C stand-in: one 256-byte EEPROM at 0x50, erased (0xFF)."""

    def __init__(self) -> None:
        self.mem = bytearray(b"\xff" * 256)

    def readfrom_mem(self, addr: int, offset: int, n: int) -> bytes:
        assert addr == 0x50
        return bytes(self.mem[offset:offset + n])

    def writeto_mem(self, addr: int, offset: int, data: bytes) -> None:
        assert addr == 0x50 and offset // 8 == (offset + len(data) - 1) // 8  # within a page
        self.mem[offset:offset + len(data)] = data


@dataclass
class Board:
    chip: ADXL355Registers
    bridge: bridge_app.Bridge
    eeprom: fixture_eeprom.FixtureEeprom


def make_board(noise_g: float = 0.0, die_c: float = -12.5,
               ids: tuple[int, int, int, int] = (0xAD, 0x1D, 0xED, 0x01)) -> Board:
    chip = ADXL355Registers(lambda: TRUE_G, lambda: die_c, noise_g=noise_g,
                            rng=np.random.default_rng(5), ids=ids)
    eeprom = fixture_eeprom.FixtureEeprom(MemI2C())
    bridge = bridge_app.Bridge(adxl355_spi.ADXL355(chip), UID, eeprom)
    return Board(chip, bridge, eeprom)


@pytest.fixture
def board() -> Board:
    return make_board()


@pytest.fixture
def pty_board(board: Board) -> Iterator[tuple[Board, PtyDevice]]:
    dev = PtyDevice(on_line=board.bridge.handle_line)
    yield board, dev
    dev.close()


# --- pure pieces ------------------------------------------------------------------------

def test_firmware_frames_exactly_like_the_host() -> None:
    rng = random.Random(3)
    for _ in range(200):
        fields = [rng.choice(["AVG", "R", "ID", "OK"])] + [
            str(rng.randint(-10**6, 10**6)) for _ in range(rng.randint(0, 11))]
        for v1 in (False, True):
            fw = bridge_proto.frame(fields, v1)
            assert fw == encode_frame(*fields, framing="v1" if v1 else "v2")
            assert bridge_proto.unframe(fw) == (fields, v1)
            assert parse_frame(fw).fields == fields
    bad = bytearray(bridge_proto.frame(["ID"]))
    bad[1] ^= 0x80
    assert bridge_proto.unframe(bytes(bad)) is None
    assert bridge_proto.unframe(b"$ID*a21b\r\n") is None  # lower-case hex is refused


def test_integer_statistics_match_numpy() -> None:
    rng = np.random.default_rng(9)
    for n in (2, 7, 400):
        counts = rng.integers(-524288, 524288, size=n)
        num = int(counts.sum())
        assert float(bridge_app.fixed(num, n, 3)) == pytest.approx(counts.mean(), abs=5e-4)
    for v in (0, 1, 2, 3, 4, 15, 16, 10**30 + 7):
        r = bridge_app.isqrt(v)
        assert r * r <= v < (r + 1) * (r + 1)
    assert bridge_app.fixed(-1, 3, 3) == "-0.333" and bridge_app.fixed(-1, 10**6, 3) == "0.000"
    for code in (0, 1885, 2111, 4095):
        assert float(bridge_app.temp_c_text(code)) == pytest.approx(
            float(adxl355.temp_raw_to_c(code)), abs=0.005)


class RecordedSensor:
    """adxl355_spi.ADXL355 stand-in replaying given samples (checks the firmware's arithmetic)."""

    def __init__(self, counts: np.ndarray, temps: np.ndarray) -> None:
        self.samples = iter(zip(counts.tolist(), temps.tolist(), strict=True))

    def configure(self, range_g: int, odr_hz: float) -> tuple[int, float]:
        return range_g, odr_hz

    def data_ready(self) -> bool:
        return True

    def sample(self) -> tuple[tuple[int, int, int], int]:
        xyz, t = next(self.samples)
        return tuple(xyz), t


def test_avg_reply_equals_numpy_on_the_same_samples() -> None:
    rng = np.random.default_rng(11)
    n = 777
    counts = rng.integers(250_000, 262_000, size=(n, 3)) * np.array([1, -1, 1])
    temps = rng.integers(2000, 2200, size=n)
    bridge = bridge_app.Bridge(RecordedSensor(counts, temps), UID)
    f = bridge.replies(["AVG", str(n)])[0]
    assert f[:2] == ["AVG", n]
    np.testing.assert_allclose([float(x) for x in f[2:5]], counts.mean(axis=0), atol=5e-4)
    np.testing.assert_allclose([float(x) for x in f[5:8]], counts.std(axis=0, ddof=1),
                               atol=1e-3)
    assert float(f[8]) == pytest.approx(temps.mean(), abs=5e-3)
    assert (f[9], f[10], f[11]) == (temps.min(), temps.max(), 0)


def test_register_access_per_datasheet(board: Board) -> None:
    sensor = board.bridge.sensor
    assert sensor.ids() == (0xAD, 0x1D, 0xED, 0x01)
    assert sensor.configure(8, 1000.0) == (8, 1000.0)
    assert board.chip.range_g == 8.0 and board.chip.odr_hz == 1000.0
    assert not board.chip.standby
    assert sensor.data_ready()
    xyz, t = sensor.sample()
    assert [c / 64_000 for c in xyz] == pytest.approx(TRUE_G, abs=1 / 64_000)
    assert adxl355.temp_raw_to_c(t) == pytest.approx(-12.5, abs=0.06)
    assert board.chip.regs[0x04] & 0x01 == 0  # reading the data cleared DATA_RDY
    assert adxl355_spi.twos20(0x80, 0x00, 0x00) == -524288
    assert adxl355_spi.twos20(0x7F, 0xFF, 0xF0) == 524287
    assert adxl355_spi.twos20(0xFF, 0xFF, 0xF0) == -1


def test_eeprom_serial_roundtrip_and_blank() -> None:
    ee = fixture_eeprom.FixtureEeprom(MemI2C())
    assert ee.read_serial() == ""
    ee.write_serial("SN-0001")
    assert ee.read_serial() == "SN-0001"


def test_main_is_micropython_shaped() -> None:
    """main.py compiles; no firmware module imports typing or __future__ (absent on the board)."""
    for path in sorted(Path(FIRMWARE_DIR).glob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        compile(tree, str(path), "exec")
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                assert node.module not in ("typing", "__future__", "dataclasses"), path
            if isinstance(node, ast.Import):
                assert not {a.name for a in node.names} & {"typing", "numpy"}, path


# --- over a pty, driven by drivers/ -------------------------------------------------------

async def test_identify_configure_acquire_over_a_pty(pty_board: tuple[Board, PtyDevice]) -> None:
    board, dev = pty_board
    board.eeprom.write_serial("SN-0001")
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=2.0)
    try:
        ident = await accel.identify()
        assert (ident.serial, ident.board_uid, ident.firmware) == ("SN-0001", UID,
                                                                    "soakcal-fw-2.3")
        assert (ident.devid_ad, ident.devid_mst, ident.partid, ident.revid) == (
            0xAD, 0x1D, 0xED, 0x01)
        await accel.configure(4.0, 250.0)
        assert (accel.range_g, accel.odr_hz) == (4.0, 250.0)
        assert board.chip.range_g == 4.0 and board.chip.odr_hz == 250.0
        for mode in ("average", "raw"):
            accel.mode = mode  # type: ignore[assignment]
            acq = await accel.acquire(40)
            np.testing.assert_allclose(acq.mean_g, TRUE_G, atol=1 / 128_000)
            assert acq.n == 40 and acq.sd_g == pytest.approx((0, 0, 0), abs=1e-9)
            assert acq.sensor_c == pytest.approx(-12.5, abs=0.06)
            assert not acq.saturated
    finally:
        await accel.close()


async def test_noise_statistics_from_the_firmware() -> None:
    board = make_board(noise_g=2e-4)
    dev = PtyDevice(on_line=board.bridge.handle_line)
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=2.0)
    try:
        acq = await accel.acquire(2000)
        # sd of 2000 samples of 2e-4 g noise: within ±6 % (≈ 4 σ of the estimate)
        np.testing.assert_allclose(acq.sd_g, 2e-4, rtol=0.06)
        np.testing.assert_allclose(acq.mean_g, TRUE_G, atol=2e-5)
    finally:
        await accel.close()
        dev.close()


async def test_refusal_and_line_faults_over_a_pty(pty_board: tuple[Board, PtyDevice]) -> None:
    board, dev = pty_board
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0)
    try:
        with pytest.raises(ConfigurationFault, match=r"ERR 3 n must be 1\.\.100000"):
            await accel.acquire(100_001)
        with pytest.raises(ConfigurationFault, match="ERR 3 range must be 2 or 4 or 8 g"):
            await accel.configure(2.0, 8000.0)  # above the ADXL355's 4 kHz
        assert sum(b"CFG" in line for line in dev.received) == 1  # refused once, not retried
        reply = board.bridge.handle_line(encode_frame("SN", "SN 1"))
        assert parse_frame(reply[0]).fields[:2] == ["ERR", "3"]
        # A high-bit byte in one reply: a framing fault (never a UnicodeError), raised to the
        # engine's guard (the one retry owner); the next call works on a fresh port.
        hits = []

        def corrupt_once(reply: bytes) -> bytes:
            if hits:
                return reply
            hits.append(reply)
            return reply[:5] + b"\xc3" + reply[6:]

        dev.inject = corrupt_once
        with pytest.raises(ProtocolError):
            await accel.identify()
        assert (await accel.identify()).partid == 0xED
        assert len(hits) == 1
        dev.inject = None
        # A command garbled on its way to the bridge: ERR 2, retried.
        reply = board.bridge.handle_line(b"$ID*0000\r\n")
        assert parse_frame(reply[0]).fields[:2] == ["ERR", "2"]
    finally:
        await accel.close()


async def test_serial_binding_through_the_fixture_eeprom(
        pty_board: tuple[Board, PtyDevice]) -> None:
    board, dev = pty_board
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0)
    try:
        with pytest.raises(SensorMismatch, match="EEPROM blank"):
            await verify_sensor(accel, "SN-0004", SerialBinding("eeprom"))
        with pytest.raises(ValueOutOfRange):
            await accel.bind_serial("SN 0004")
        assert await accel.bind_serial(" SN-0004 ") == "SN-0004"
        assert (await verify_sensor(accel, "SN-0004", SerialBinding())).bound_by == "eeprom"
        with pytest.raises(SensorMismatch, match="names sensor SN-0005 but SN-0004"):
            await verify_sensor(accel, "SN-0005", SerialBinding())
    finally:
        await accel.close()


async def test_unwired_sensor_and_stalled_data() -> None:
    board = make_board(ids=(0, 0, 0, 0))
    board.bridge.eeprom = None  # and a fixture without EEPROM
    dev = PtyDevice(on_line=board.bridge.handle_line)
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0)
    try:
        with pytest.raises(ConfigurationFault, match="ERR 4 no fixture EEPROM"):
            await accel.bind_serial("SN-1")
        with pytest.raises(SensorMismatch, match="check wiring"):
            await verify_sensor(accel, "SN-1", SerialBinding("any"))
        board.chip.regs[0x2D] = 0x01  # sensor fell back to standby: DATA_RDY never sets
        with pytest.raises(ExceptionReply, match="ERR 5") as err:
            await accel.acquire(3)
        assert err.value.retryable
    finally:
        await accel.close()
        dev.close()


async def test_v1_host_against_the_firmware(pty_board: tuple[Board, PtyDevice]) -> None:
    _, dev = pty_board
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0, framing="v1")
    try:
        ident = await accel.identify()
        assert (ident.model, ident.partid, ident.protocol) == ("ADXL355", None, "v1")
        np.testing.assert_allclose((await accel.acquire(5)).mean_g, TRUE_G, atol=1 / 256_000)
    finally:
        await accel.close()


async def test_plain_streaming_mode_read_by_the_host() -> None:
    board = make_board(noise_g=1e-4, die_c=31.0)
    dev = PtyDevice(stream=board.bridge.stream_line)
    accel = StreamingAccelerometer(dev.path, VirtualClock(), fmt=StreamFormat(), timeout_s=1.0)
    try:
        acq = await accel.acquire(500)
        assert acq.n == 500
        np.testing.assert_allclose(acq.mean_g, TRUE_G, atol=3e-5)
        np.testing.assert_allclose(acq.sd_g, 1e-4, rtol=0.15)
        assert acq.sensor_c == pytest.approx(31.0, abs=0.06)
        assert (await accel.identify()).protocol == "stream"
    finally:
        await accel.close()
        dev.close()
