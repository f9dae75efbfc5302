"""Heap a RAW reply needs on the sensor bridge: the reference firmware served under CPython.

The firmware (firmware/rp2040) runs unchanged under CPython; tracemalloc measures the peak
bytes allocated while ``MuxBridge.serve_line`` answers one ``RAW,<n>`` with a synthetic
sensor (samples made when read), for the streamed reply (each frame written as made) and
for a reply built whole first (``handle_line``, what firmware 2.2 did). The largest single
write is the chunk the board's USB stack sees.

    .venv/bin/python benchmarks/bench_firmware_raw_heap.py
"""

from __future__ import annotations

import contextlib
import sys
import tracemalloc
from collections.abc import Iterator
from pathlib import Path
from typing import Any

FIRMWARE_DIR = Path(__file__).resolve().parents[1] / "firmware" / "rp2040"
if str(FIRMWARE_DIR) not in sys.path:
    sys.path.insert(0, str(FIRMWARE_DIR))

import bridge_app  # noqa: E402  (the board's flat module, found on FIRMWARE_DIR)

from drivers.bridge_protocol import encode_frame  # noqa: E402

UID = "E6614104035F2B2F"


class SyntheticSensor:
    """adxl355_spi.ADXL355 stand-in making each sample when read (stores nothing).

    ``stall_after``: DATA_RDY never sets again after that many samples (sensor stopped).
    """

    def __init__(self, stall_after: int | None = None) -> None:
        self.i = 0
        self.stall_after = stall_after

    def configure(self, range_g: int, odr_hz: float) -> tuple[int, float]:
        return range_g, odr_hz

    def ids(self) -> tuple[int, int, int, int]:
        return 0xAD, 0x1D, 0xED, 0x01

    def data_ready(self) -> bool:
        return self.stall_after is None or self.i < self.stall_after

    def sample(self) -> tuple[tuple[int, int, int], int]:
        self.i += 1
        i = self.i
        return ((i * 7919) % 524288 - 262144, -(i * 104729) % 524287, 250000 - i % 977), \
            1800 + i % 300


class WriteMeter:
    """The board's ``write``: keeps no data, only the largest write, the count and the bytes'
    total (optionally the bytes themselves, for small captures)."""

    def __init__(self, keep: bool = False) -> None:
        self.largest = 0
        self.writes = 0
        self.total = 0
        self.kept: list[bytes] | None = [] if keep else None

    def __call__(self, data: bytes) -> None:
        self.largest = max(self.largest, len(data))
        self.writes += 1
        self.total += len(data)
        if self.kept is not None:
            self.kept.append(data)


def mux(stall_after: int | None = None) -> bridge_app.MuxBridge:
    return bridge_app.MuxBridge({0: bridge_app.Bridge(SyntheticSensor(stall_after), UID),
                                 1: bridge_app.Bridge(SyntheticSensor(stall_after), UID)})


@contextlib.contextmanager
def _alone() -> Iterator[None]:
    """No other Python thread runs inside (tracemalloc counts every thread's allocations: a
    test process may serve a web app from a thread beside it). The code measured writes to
    memory only and never blocks, so holding the GIL for the switch interval holds it
    throughout."""
    before = sys.getswitchinterval()
    sys.setswitchinterval(60.0)
    try:
        yield
    finally:
        sys.setswitchinterval(before)


def peak_heap_serving(line: bytes) -> tuple[int, WriteMeter]:
    """Peak bytes allocated (tracemalloc) while the firmware serves ``line``."""
    board = mux()
    meter = WriteMeter()
    with _alone():
        return _peak_serving(board, line, meter), meter


def _peak_serving(board: Any, line: bytes, meter: WriteMeter) -> int:
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        board.serve_line(line, meter)
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


def peak_heap_buffered(line: bytes) -> int:
    """Peak bytes allocated while the whole reply to ``line`` is built as a list first."""
    board = mux()
    with _alone():
        tracemalloc.start()
        try:
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            board.handle_line(line)
            return tracemalloc.get_traced_memory()[1] - base
        finally:
            tracemalloc.stop()


def main() -> None:
    print("| n (RAW) | streamed peak, bytes | largest write, bytes | writes | "
          "whole reply first, peak bytes |")
    print("|---|---|---|---|---|")
    for n in (200, 2_000, 10_000, 100_000):
        line = encode_frame("RAW", n)
        peak, meter = peak_heap_serving(line)
        buffered = peak_heap_buffered(line) if n <= 10_000 else None
        print(f"| {n} | {peak} | {meter.largest} | {meter.writes} | "
              f"{buffered if buffered is not None else 'not run'} |")


if __name__ == "__main__":
    main()
