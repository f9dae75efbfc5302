"""One injectable clock for all waiting in soakcal.

Nothing in the engine, drivers or simulators calls ``time.time()`` or
``time.sleep()``: they take a :class:`Clock`. Three kinds exist:

* :class:`RealClock` -- wall time (a real rig).
* :class:`ScaledClock` -- simulated time runs ``factor`` times faster than the
  wall clock (``soakcal serve --sim-speed 600``); sockets still carry every byte.
* :class:`VirtualClock` -- time advances only when every waiter is asleep
  (discrete-event style), so a 15-hour campaign runs as fast as the CPU allows.
  Used by the tests and ``soakcal demo``.

A driver whose I/O blocks runs it with :func:`run_blocking` (on its own threads) and
marks the waits for its device with :func:`awaiting_device`: a :class:`VirtualClock`
watching the event loop (``idle="loop"``) then knows when that thread is busy.

All three expose the same small async interface: ``now()`` in seconds since
the clock's epoch and ``await sleep(seconds)``.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import heapq
import itertools
import threading
import time as _time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Literal, Protocol, TypeVar, runtime_checkable

T = TypeVar("T")


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
    real loop iterations to deliver bytes) and, once the world is idle, advances
    ``now()`` to the earliest wake-up. How it decides the world is idle:

    * ``idle="wall"`` (the default): no I/O has been pending for ``idle_wall_s`` of wall
      time. ``idle_wall_s`` trades speed for safety: it must exceed the time a loopback
      round-trip needs, otherwise time could jump while a reply is in flight. The
      default (1 ms) is ~20× a loopback Modbus round-trip on this class of machine; an
      idle wait is never shorter than 1 ms (the selector's resolution), so a campaign of
      thousands of waits spends seconds of wall time in them.
    * ``idle="loop"``: the event loop has nothing to run (no ready callback, no timer due
      within ``idle_wall_s``) for :data:`QUIET_TURNS` turns in a row, each turn polling
      the sockets once (a loopback ``send`` has put its bytes in the peer's buffer by the
      time it returns, so the next poll sees them), and no blocking call started with
      :func:`run_blocking` is running, except one waiting for its device
      (:func:`awaiting_device`) with nothing arrived for it. No wall-time window: a jump
      costs tens of µs, not a millisecond, and a loaded host cannot make time jump while a
      reply is in flight. A blocking call that never says it is waiting (a driver not
      marked) holds time for at most ``stall_wall_s`` of wall time, then time moves on as
      it would in ``"wall"`` mode. Everything must run on this process's event loop or
      through :func:`run_blocking` (``soakcal demo``: the simulated rig on loopback).
    """

    def __init__(self, start_s: float = 0.0, idle_wall_s: float = 0.001, *,
                 idle: Literal["wall", "loop"] = "wall", stall_wall_s: float = 0.5) -> None:
        if idle not in ("wall", "loop"):
            raise ValueError(f"idle must be 'wall' or 'loop', got {idle!r}")
        self._now_s = float(start_s)
        self._heap: list[_Waiter] = []
        self._seq = itertools.count()
        self._idle_wall_s = idle_wall_s
        self._runner: asyncio.Task | None = None
        self.idle = idle
        self._stall_wall_s = stall_wall_s
        # Blocking calls in flight (idle="loop"), shared with their threads under _lock.
        self._lock = threading.Lock()
        self._calls: set[_BlockingCall] = set()
        self._changed: asyncio.Event | None = None
        self._poke_wanted = False
        self._loop: asyncio.AbstractEventLoop | None = None

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
            if self.idle == "loop":
                await self._until_quiet()
            else:
                # Let ready callbacks and socket I/O run before deciding the world is idle.
                await asyncio.sleep(self._idle_wall_s)
            self._drop_cancelled()
            if not self._heap:
                break
            self._now_s = max(self._now_s, self._heap[0].wake_s)
            self._wake_due()

    # --- idle="loop" ---------------------------------------------------------------
    async def _until_quiet(self) -> None:
        """Return once the loop and the blocking calls are quiet (class docstring)."""
        loop = asyncio.get_running_loop()
        if loop is not self._loop:  # first use, or a clock carried over to a new loop
            self._loop, self._changed = loop, asyncio.Event()
        quiet = 0
        while quiet < QUIET_TURNS:
            await asyncio.sleep(0)  # one turn: the loop polls its sockets, runs what is ready
            idle = _loop_idle(loop, self._idle_wall_s)
            if idle is None:  # a loop we cannot look into: the wall window instead
                await asyncio.sleep(self._idle_wall_s)
                idle, quiet = True, QUIET_TURNS - 1
            if not idle:
                quiet = 0
            elif self._calls_quiet(look=quiet == QUIET_TURNS - 1):  # the ports: last turn
                quiet += 1
            elif await self._wait_for_calls(loop):
                quiet = 0  # a blocking call changed state: look again
            else:
                return  # stalled: a call that never says it waits; move on as "wall" would

    def _calls_quiet(self, look: bool = True) -> bool:
        """No blocking call running, and (``look``) none with input waiting for its reader
        (a system call per call: asked on the turn that decides only)."""
        with self._lock:
            calls = list(self._calls)
        for call in calls:
            if call.has_input is None:
                return False  # running: it may be about to send, or reading a reply
            if not look:
                continue
            try:
                if call.has_input():
                    return False  # its reply has arrived; its thread has yet to read it
            except Exception:  # noqa: BLE001 - a port closing under us: not quiet yet
                return False
        return True

    async def _wait_for_calls(self, loop: asyncio.AbstractEventLoop) -> bool:
        """Wait until a blocking call changes state; ``False`` if none did within
        ``stall_wall_s`` (a call that runs without saying it waits)."""
        changed = self._changed
        assert changed is not None  # made with _loop in _until_quiet
        changed.clear()
        with self._lock:
            self._poke_wanted = True
        if self._calls_quiet():  # changed between the first look and the flag
            with self._lock:
                self._poke_wanted = False
            return True
        timer = loop.call_later(self._stall_wall_s, changed.set)
        await changed.wait()
        timer.cancel()
        with self._lock:
            poked = not self._poke_wanted
            self._poke_wanted = False
        return poked

    def _poke(self, *, from_loop: bool = False) -> None:
        """A blocking call changed state (``_lock`` held): wake the runner if it waits."""
        if not self._poke_wanted or self._loop is None or self._changed is None:
            return
        self._poke_wanted = False
        if from_loop:
            self._changed.set()
            return
        with contextlib.suppress(RuntimeError):  # the loop has closed: nothing waits
            self._loop.call_soon_threadsafe(self._changed.set)

    async def run_blocking(self, executor: Executor | None, fn: Callable[..., T],
                           *args: object) -> T:
        """``fn(*args)`` on ``executor``, tracked (``idle="loop"``): use :func:`run_blocking`."""
        loop = asyncio.get_running_loop()
        call = _BlockingCall(self)
        with self._lock:
            self._calls.add(call)
        try:
            return await loop.run_in_executor(executor, call.run, fn, args)
        finally:
            with self._lock:
                self._calls.discard(call)
                self._poke(from_loop=True)

    # --- both ------------------------------------------------------------------------
    def _drop_cancelled(self) -> None:
        while self._heap and self._heap[0].future.done():
            heapq.heappop(self._heap)

    def _wake_due(self) -> None:
        while self._heap and self._heap[0].wake_s <= self._now_s:
            w = heapq.heappop(self._heap)
            if not w.future.done():
                w.future.set_result(None)


#: Turns of an empty event loop in a row before a ``VirtualClock(idle="loop")`` jumps: the
#: first may follow a ``send`` on loopback whose reader the loop has not yet polled; the
#: second has polled it.
QUIET_TURNS = 2


def _loop_idle(loop: asyncio.AbstractEventLoop, within_s: float) -> bool | None:
    """Nothing ready to run on ``loop`` and no timer due within ``within_s``.

    Reads the ready queue and timer heap of asyncio's own loop (``_ready``,
    ``_scheduled``); None for a loop without them (another implementation): the runner
    then waits the wall window of ``"wall"`` mode instead.
    """
    ready = getattr(loop, "_ready", None)
    scheduled = getattr(loop, "_scheduled", None)
    if ready is None or scheduled is None:
        return None
    if ready:
        return False
    return not scheduled or scheduled[0].when() - loop.time() > within_s


_current_call = threading.local()


class _BlockingCall:
    """One blocking call of :meth:`VirtualClock.run_blocking`: running, or waiting for its
    device (``has_input`` set: whether the device's reply has arrived)."""

    __slots__ = ("clock", "has_input")

    def __init__(self, clock: VirtualClock) -> None:
        self.clock = clock
        self.has_input: Callable[[], bool] | None = None

    def run(self, fn: Callable[..., T], args: tuple[object, ...]) -> T:
        _current_call.call = self
        try:
            return fn(*args)
        finally:
            _current_call.call = None

    def waiting(self, has_input: Callable[[], bool] | None) -> None:
        with self.clock._lock:
            self.has_input = has_input
            if has_input is not None:
                self.clock._poke()


async def run_blocking(clock: Clock, executor: Executor | None, fn: Callable[..., T],
                       *args: object) -> T:
    """``fn(*args)`` on ``executor``'s threads, awaited.

    A :class:`VirtualClock` watching the loop (``idle="loop"``) holds time still while the
    call runs, except while it waits for its device (:func:`awaiting_device`); any other
    clock: a plain ``run_in_executor``.
    """
    if isinstance(clock, VirtualClock) and clock.idle == "loop":
        return await clock.run_blocking(executor, fn, *args)
    loop = asyncio.get_running_loop()
    return await loop.run_in_executor(executor, functools.partial(fn, *args))


@contextlib.contextmanager
def awaiting_device(has_input: Callable[[], bool]) -> Iterator[None]:
    """Inside a :func:`run_blocking` call: the thread now waits for its device (a reply,
    a sample), which may need simulated time to pass; ``has_input()`` says whether
    something has arrived for it (then time holds until the thread has read it).
    Anywhere else: nothing."""
    call: _BlockingCall | None = getattr(_current_call, "call", None)
    if call is None:
        yield
        return
    call.waiting(has_input)
    try:
        yield
    finally:
        call.waiting(None)
