"""Heap a RAW reply needs on the sensor bridge: the reference firmware served under CPython.

The firmware (firmware/rp2040) runs unchanged under CPython; tracemalloc measures the peak
bytes allocated while ``MuxBridge.serve_line`` answers one ``RAW,<n>`` with a synthetic
sensor (samples made when read), for the streamed reply (each frame written as made) and
for a reply built whole first (``handle_line``, what firmware 2.2 did). The largest single
write is the chunk the board's USB stack sees. Each measurement runs in a process of its own
(tracemalloc counts every thread of a process).

    .venv/bin/python benchmarks/bench_firmware_raw_heap.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tracemalloc
from pathlib import Path

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


def _measure_in_child(mode: str, line: bytes) -> dict[str, int]:
    """Run one measurement in a fresh interpreter and return what it printed.

    tracemalloc counts every thread's allocations, and a test process may serve a web app
    from a thread beside this one (the browser tests' live service counted 32 kB so; holding
    the GIL through a long switch interval did not keep it out: a thread already waiting for
    the GIL takes it at the old interval). A child process has no other thread.
    """
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(root), env.get("PYTHONPATH")]))
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_firmware_raw_heap", "--child", mode,
         line.hex()],
        cwd=root, env=env, capture_output=True, text=True, timeout=120, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"heap measurement in a child process failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def peak_heap_serving(line: bytes) -> tuple[int, WriteMeter]:
    """Peak bytes allocated (tracemalloc) while the firmware serves ``line``, measured in a
    process of its own; the meter holds that process' largest write, count and total."""
    got = _measure_in_child("serve", line)
    meter = WriteMeter()
    meter.largest, meter.writes, meter.total = got["largest"], got["writes"], got["total"]
    return got["peak"], meter


def peak_heap_buffered(line: bytes) -> int:
    """Peak bytes allocated while the whole reply to ``line`` is built as a list first."""
    return _measure_in_child("buffered", line)["peak"]


def _peak_here(mode: str, line: bytes) -> dict[str, int]:
    """The measurement itself, in this process (the child's side of ``_measure_in_child``)."""
    board = mux()
    meter = WriteMeter()
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        if mode == "serve":
            board.serve_line(line, meter)
        else:
            board.handle_line(line)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return {"peak": peak, "largest": meter.largest, "writes": meter.writes,
            "total": meter.total}


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
    if len(sys.argv) == 4 and sys.argv[1] == "--child":
        print(json.dumps(_peak_here(sys.argv[2], bytes.fromhex(sys.argv[3]))))
    else:
        main()
