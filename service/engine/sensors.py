"""A campaign's sensors: read together, judged one by one, given up alone.

A campaign has one sensor or several (issue 12); the engine treats one as a
list of one. Every sensor call goes through the engine's one retry policy,
:meth:`service.engine.guard.DeviceGuard.call`: a transient fault is retried
with back-off on the injected clock. What happens when the retries run out
depends on what is left: while another sensor still reads, the failing one is
given up (``give_up`` raises :class:`SensorDropped`; the engine records the
reason and goes on with the others) instead of suspending every good sensor
for one bad one; the last sensor left suspends the campaign, and its
configuration fault fails it, as any other device's. A reading out of range
for a static sensor (:func:`reading_problem`) is a sensor fault too.

The sensors of a position are read at once (:func:`read_all`): each bridge
captures on its own, so a position of eight sensors takes about one capture
time, not eight, on the one injectable clock (the simulated bridges overlap in
virtual time as real ones do on the wall).

Each die's soak decision, and the slowest one ending the soak, are the soak
poll's answer (:mod:`service.engine.polls`).
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable, Sequence
from typing import TypeVar

from drivers.protocols import Acquisition

T = TypeVar("T")
# A static accelerometer reads gravity: |a| ≈ 1 g. Beyond this band the reading is not a
# plausible gravity vector (a loose part, a dead axis, a sensor shorted to a rail).
GRAVITY_BAND_G = (0.5, 1.5)
SATURATION_FRACTION = 0.98  # |mean| this close to the range limit: the axis is clipped


class SensorDropped(Exception):
    """A sensor is given up; ``reason`` goes to the campaign (:meth:`CampaignRunner._drop`)."""

    def __init__(self, serial: str, reason: str) -> None:
        super().__init__(f"sensor {serial}: {reason}")
        self.serial = serial
        self.reason = reason


async def read_all(serials: Sequence[str], read: Callable[[str], Awaitable[T]]
                   ) -> dict[str, T | SensorDropped]:
    """``read(serial)`` for every serial concurrently: the result, or the
    :class:`SensorDropped` it raised (the caller drops it; the others' readings stand).

    Any other exception (an abort, a cancellation, an engine bug) cancels the reads
    still running and is raised once they have all ended, so no capture outlives it.
    """

    async def one(serial: str) -> T | SensorDropped:
        try:
            return await read(serial)
        except SensorDropped as exc:
            return exc

    tasks = [asyncio.ensure_future(one(s)) for s in serials]
    try:
        results = await asyncio.gather(*tasks)
    except BaseException:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        raise
    return dict(zip(serials, results, strict=True))


def reading_problem(acq: Acquisition, range_g: float) -> str | None:
    """Why an averaged reading is out of range for a static sensor; ``None`` when plausible."""
    mean = [float(v) for v in acq.mean_g]
    if not all(math.isfinite(v) for v in (*mean, float(acq.sensor_c))):
        return f"reading out of range: non-finite value {mean} g, {acq.sensor_c} °C"
    if max(abs(v) for v in mean) >= SATURATION_FRACTION * range_g:
        return f"reading out of range: an axis at the ±{range_g:g} g limit ({mean} g)"
    norm_g = math.sqrt(sum(v * v for v in mean))
    lo, hi = GRAVITY_BAND_G
    if not lo <= norm_g <= hi:
        return (f"reading out of range: |a| = {norm_g:.3f} g outside {lo:g}…{hi:g} g "
                f"for a static sensor")
    return None
