"""Pure parts of the several-sensor engine: out-of-range readings, the slowest die decides."""

from __future__ import annotations

import asyncio
import math

import pytest

from drivers.clock import VirtualClock
from drivers.protocols import Acquisition
from service.engine.guard import AbortRequested
from service.engine.polls import slowest_decision
from service.engine.sensors import SensorDropped, read_all, reading_problem
from service.engine.stability import Decision


def _acq(mean_g: tuple[float, float, float], sensor_c: float = 25.0) -> Acquisition:
    return Acquisition(mean_g, (1e-4,) * 3, 200, sensor_c, 0.01, False, 3.2)


def test_reading_problem() -> None:
    assert reading_problem(_acq((0.01, -0.02, 0.99)), 2.0) is None
    assert "limit" in (reading_problem(_acq((0.0, 0.0, 1.99)), 2.0) or "")
    assert "|a| = 0.010 g" in (reading_problem(_acq((0.0, 0.0, 0.01)), 2.0) or "")
    assert "non-finite" in (reading_problem(_acq((math.nan, 0.0, 1.0)), 2.0) or "")
    assert "non-finite" in (reading_problem(_acq((0.0, 0.0, 1.0), math.inf), 2.0) or "")


def test_the_slowest_die_decides() -> None:
    fast = Decision(True, "predicted", tau_s=300.0)
    slow = Decision(True, "predicted", tau_s=900.0)
    waiting = Decision(False, "waiting", tau_s=1200.0)
    assert slowest_decision([fast, slow]) is slow
    assert slowest_decision([fast, waiting, slow]) is waiting
    capped = Decision(True, "max soak", tau_s=100.0, max_soak_reached=True)
    assert slowest_decision([slow, capped]) is capped
    with pytest.raises(ValueError):
        slowest_decision([])


async def test_read_all_overlaps_the_reads_and_returns_a_drop_in_place_of_its_reading() -> None:
    clock = VirtualClock(idle_wall_s=0.0)

    async def read(serial: str) -> str:
        await clock.sleep(10.0)
        if serial == "B":
            raise SensorDropped(serial, "no answer")
        return f"reading {serial}"

    got = await read_all(["A", "B", "C"], read)
    assert clock.now() == pytest.approx(10.0)  # at once: one read's time, not three
    assert got["A"] == "reading A" and got["C"] == "reading C"
    assert isinstance(got["B"], SensorDropped) and got["B"].reason == "no answer"


async def test_an_abort_in_one_read_cancels_the_others_before_it_is_raised() -> None:
    clock = VirtualClock(idle_wall_s=0.01)  # the abort reaches read_all before time jumps
    cancelled: list[str] = []

    async def read(serial: str) -> str:
        if serial == "A":
            await clock.sleep(1.0)
            raise AbortRequested("operator")
        try:
            await clock.sleep(100.0)
        except asyncio.CancelledError:
            cancelled.append(serial)
            raise
        return serial

    with pytest.raises(AbortRequested):
        await read_all(["A", "B", "C"], read)
    assert sorted(cancelled) == ["B", "C"]  # no capture outlives the abort
