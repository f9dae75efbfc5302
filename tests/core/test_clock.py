"""The injectable clocks: virtual time jumps, scaled time scales, ordering is kept."""

import asyncio
import select
import socket
import threading
import time

import pytest

from drivers.clock import ScaledClock, VirtualClock, awaiting_device, run_blocking


async def test_virtual_clock_runs_an_hour_instantly_and_in_order() -> None:
    clock = VirtualClock()
    woke: list[tuple[str, float]] = []

    async def sleeper(name: str, dt_s: float) -> None:
        await clock.sleep(dt_s)
        woke.append((name, clock.now()))

    await asyncio.wait_for(
        asyncio.gather(sleeper("late", 3600.0), sleeper("early", 60.0), sleeper("mid", 600.0)),
        timeout=5.0,
    )
    assert [n for n, _ in woke] == ["early", "mid", "late"]
    assert [t for _, t in woke] == [60.0, 600.0, 3600.0]


async def test_virtual_clock_waits_for_pending_io_before_jumping() -> None:
    clock = VirtualClock()
    order: list[str] = []

    async def io_bound() -> None:
        await asyncio.sleep(0)  # real loop iteration, like a socket read
        order.append(f"io@{clock.now()}")

    async def waiter() -> None:
        await clock.sleep(100.0)
        order.append(f"timer@{clock.now()}")

    await asyncio.gather(waiter(), io_bound())
    assert order == ["io@0.0", "timer@100.0"]


async def test_cancelled_sleeper_does_not_block_others() -> None:
    clock = VirtualClock()
    task = asyncio.create_task(clock.sleep(10.0))
    await asyncio.sleep(0)
    task.cancel()
    await clock.sleep(20.0)
    assert clock.now() == 20.0


def test_virtual_clock_manual_advance() -> None:
    clock = VirtualClock(start_s=5.0)
    clock.advance(2.5)
    assert clock.now() == 7.5


async def test_scaled_clock_sleeps_factor_times_faster() -> None:
    clock = ScaledClock(factor=1000.0)
    t0 = clock.now()
    await clock.sleep(50.0)  # 50 ms of wall time
    assert clock.now() - t0 >= 50.0


def test_scaled_clock_rejects_nonpositive_factor() -> None:
    with pytest.raises(ValueError, match="factor"):
        ScaledClock(factor=0)


# --- idle="loop": time jumps when the loop and the blocking calls are quiet ------------------

async def test_loop_clock_runs_sleepers_in_order() -> None:
    clock = VirtualClock(idle="loop")
    woke: list[tuple[str, float]] = []

    async def sleeper(name: str, dt_s: float) -> None:
        await clock.sleep(dt_s)
        woke.append((name, clock.now()))

    await asyncio.wait_for(asyncio.gather(sleeper("late", 3600.0), sleeper("early", 60.0)),
                           timeout=5.0)
    assert woke == [("early", 60.0), ("late", 3600.0)]


async def test_loop_clock_holds_while_a_loopback_reply_is_in_flight() -> None:
    """A request and its reply over a real socket pair, both ends on the loop: no jump
    between them, however long the loop takes to carry the bytes."""
    clock = VirtualClock(idle="loop")
    served_at: list[float] = []

    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        line = await reader.readline()
        served_at.append(clock.now())
        writer.write(line.upper())
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    timer = asyncio.ensure_future(clock.sleep(100.0))
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(b"ping\n")
    assert await reader.readline() == b"PING\n"
    replied_at = clock.now()
    writer.close()
    server.close()
    await timer
    assert served_at == [0.0] and replied_at == 0.0 and clock.now() == 100.0


async def test_loop_clock_holds_while_a_blocking_call_runs() -> None:
    clock = VirtualClock(idle="loop")
    seen: list[str] = []

    def work() -> None:
        time.sleep(0.05)  # wall time: 50 idle waits of a "wall" clock

    async def timer() -> None:
        await clock.sleep(10.0)
        seen.append(f"timer@{clock.now()}")

    async def call() -> None:
        await run_blocking(clock, None, work)
        seen.append(f"call@{clock.now()}")

    await asyncio.gather(timer(), call())
    assert seen == ["call@0.0", "timer@10.0"]


async def test_loop_clock_moves_while_a_blocking_call_awaits_its_device() -> None:
    """The device answers after 5 s of clock time: marked as waiting for it, the thread
    gets its reply at 5 s (unmarked, the clock would hold for ``stall_wall_s``)."""
    clock = VirtualClock(idle="loop", stall_wall_s=60.0)
    host_end, device_end = socket.socketpair()

    def has_input() -> bool:
        return bool(select.select([host_end], [], [], 0)[0])

    def read_reply() -> float:
        with awaiting_device(has_input):
            host_end.recv(1)
        return clock.now()

    async def device() -> None:
        await clock.sleep(5.0)
        device_end.send(b"x")

    try:
        got_at, _ = await asyncio.wait_for(
            asyncio.gather(run_blocking(clock, None, read_reply), device()), timeout=10.0)
    finally:
        host_end.close()
        device_end.close()
    assert got_at == 5.0


async def test_loop_clock_holds_while_input_waits_for_its_reader() -> None:
    """A reply has arrived (``has_input``) but the thread has not read it: no jump."""
    clock = VirtualClock(idle="loop")

    def slow_reader() -> float:
        with awaiting_device(lambda: True):
            time.sleep(0.05)
        return clock.now()

    timer = asyncio.ensure_future(clock.sleep(10.0))
    assert await run_blocking(clock, None, slow_reader) == 0.0
    await timer
    assert clock.now() == 10.0


async def test_loop_clock_moves_on_after_a_stalled_unmarked_call() -> None:
    """A blocking call that waits for clock time without saying so holds time only for
    ``stall_wall_s``."""
    clock = VirtualClock(idle="loop", stall_wall_s=0.05)
    answered = threading.Event()

    def wait_unmarked() -> bool:
        return answered.wait(timeout=30.0)

    async def device() -> None:
        await clock.sleep(5.0)
        answered.set()

    got, _ = await asyncio.wait_for(
        asyncio.gather(run_blocking(clock, None, wait_unmarked), device()), timeout=10.0)
    assert got and clock.now() == 5.0


def test_virtual_clock_rejects_an_unknown_idle_rule() -> None:
    with pytest.raises(ValueError, match="idle"):
        VirtualClock(idle="sometimes")  # type: ignore[arg-type]


async def test_loop_clock_on_a_loop_it_cannot_look_into_waits_the_wall_window(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Another event loop implementation (no ready queue to read): time still moves, after
    the wall window each jump, as in ``"wall"`` mode."""
    import drivers.clock as clock_mod

    monkeypatch.setattr(clock_mod, "_loop_idle", lambda loop, within_s: None)
    clock = VirtualClock(idle="loop")
    await asyncio.wait_for(asyncio.gather(clock.sleep(60.0), clock.sleep(30.0)), timeout=5.0)
    assert clock.now() == 60.0
