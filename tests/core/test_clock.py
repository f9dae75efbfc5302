"""The injectable clocks: virtual time jumps, scaled time scales, ordering is kept."""

import asyncio

import pytest

from drivers.clock import ScaledClock, VirtualClock


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
