"""One injectable clock for all waiting in soakcal.

Nothing in the engine, drivers or simulators calls ``time.time()`` or
``time.sleep()``: they take a :class:`Clock`. Three kinds exist:

* :class:`RealClock` -- wall time (a real rig).
* :class:`ScaledClock` -- simulated time runs ``factor`` times faster than the
  wall clock (``soakcal serve --sim-speed 600``); sockets still carry every byte.
* :class:`VirtualClock` -- time advances only when every waiter is asleep
  (discrete-event style), so a 15-hour campaign runs as fast as the CPU allows.
  Used by the tests and ``soakcal demo``.

All three expose the same small async interface: ``now()`` in seconds since
the clock's epoch and ``await sleep(seconds)``.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time as _time
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    """Time source: ``now()`` in s, ``sleep(dt_s)`` awaits ``dt_s`` of this clock's time."""

    def now(self) -> float: ...

    async def sleep(self, dt_s: float) -> None: ...


class RealClock:
    """Wall-clock time (monotonic), for real rigs."""

    def __init__(self) -> None:
        self._t0 = _time.monotonic()

    def now(self) -> float:
        return _time.monotonic() - self._t0

    async def sleep(self, dt_s: float) -> None:
        await asyncio.sleep(max(0.0, dt_s))


class ScaledClock:
    """Simulated time running ``factor`` times faster than the wall clock.

    ``now()`` is ``factor × (wall time since start) + offset_s``. Sleeping ``dt``
    simulated seconds waits ``dt / factor`` wall seconds.
    """

    def __init__(self, factor: float = 600.0, offset_s: float = 0.0) -> None:
        if factor <= 0:
            raise ValueError(f"clock speed factor must be > 0, got {factor}")
        self.factor = float(factor)
        self._t0 = _time.monotonic()
        self._offset_s = offset_s

    def now(self) -> float:
        return (_time.monotonic() - self._t0) * self.factor + self._offset_s

    async def sleep(self, dt_s: float) -> None:
        await asyncio.sleep(max(0.0, dt_s) / self.factor)


@dataclass(order=True)
class _Waiter:
    wake_s: float
    seq: int
    future: asyncio.Future = field(compare=False)


class VirtualClock:
    """Discrete-event clock: time jumps to the next wake-up when nothing else can run.

    Coroutines that ``await clock.sleep(dt)`` are parked in a heap. A background
    task lets the event loop drain real I/O (sockets on loopback still need a few
    real loop iterations to deliver bytes) and, once no I/O has been pending for
    ``idle_wall_s`` of wall time, advances ``now()`` to the earliest wake-up.

    ``idle_wall_s`` trades speed for safety: it must exceed the time a loopback
    round-trip needs, otherwise time could jump while a reply is in flight. The
    default (1 ms) is ~20× a loopback Modbus round-trip on this class of machine.
    """

    def __init__(self, start_s: float = 0.0, idle_wall_s: float = 0.001) -> None:
        self._now_s = float(start_s)
        self._heap: list[_Waiter] = []
        self._seq = itertools.count()
        self._idle_wall_s = idle_wall_s
        self._runner: asyncio.Task | None = None

    def now(self) -> float:
        return self._now_s

    async def sleep(self, dt_s: float) -> None:
        loop = asyncio.get_running_loop()
        fut: asyncio.Future = loop.create_future()
        heapq.heappush(self._heap, _Waiter(self._now_s + max(0.0, dt_s), next(self._seq), fut))
        self._ensure_runner(loop)
        try:
            await fut
        except asyncio.CancelledError:
            # Leave the cancelled waiter in the heap; _advance skips done futures.
            raise

    def advance(self, dt_s: float) -> None:
        """Jump forward by ``dt_s`` (tests that drive time by hand), waking due sleepers."""
        self._now_s += dt_s
        self._wake_due()

    def _ensure_runner(self, loop: asyncio.AbstractEventLoop) -> None:
        if self._runner is None or self._runner.done():
            self._runner = loop.create_task(self._run(), name="virtual-clock")

    async def _run(self) -> None:
        while self._heap:
            # Let ready callbacks and socket I/O run before deciding the world is idle.
            await asyncio.sleep(self._idle_wall_s)
            self._drop_cancelled()
            if not self._heap:
                break
            self._now_s = max(self._now_s, self._heap[0].wake_s)
            self._wake_due()

    def _drop_cancelled(self) -> None:
        while self._heap and self._heap[0].future.done():
            heapq.heappop(self._heap)

    def _wake_due(self) -> None:
        while self._heap and self._heap[0].wake_s <= self._now_s:
            w = heapq.heappop(self._heap)
            if not w.future.done():
                w.future.set_result(None)
