"""Rig row → devices: the one place that knows which drivers a rig's config means.

``open_rig(rig_config, clock)`` is an async context manager yielding
:class:`RigDevices`. The ``sim`` driver starts the simulated rig
(``simulators.rig.start_sim_rig``) and connects to it through the real
drivers over loopback sockets (``simulators.rig.connect_rig``), so the engine
exercises the same code path as on a real rig. A real rig's config (Modbus
host/port/unit, serial port) will map to the real drivers here the same way.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.clock import Clock
from drivers.protocols import Accelerometer, Chamber, Turntable

AnglesFor = Callable[[np.ndarray], tuple[float, ...]]


@dataclass
class RigDevices:
    chamber: Chamber
    turntable: Turntable
    accelerometer: Accelerometer
    # Maps a scheduled gravity direction (sensor frame, unit) to table angles: rig geometry.
    angles_for: AnglesFor


@asynccontextmanager
async def open_rig(
    rig: dict[str, Any], clock: Clock, *, seed: int = 0, faults: Any = None,
    sim_options: dict[str, Any] | None = None,
) -> AsyncIterator[RigDevices]:
    """Devices for a rig config ``{"name", "chamber", "turntable", "sensors"}``."""
    driver = str((rig.get("chamber") or {}).get("driver", "sim"))
    if driver != "sim":
        raise NotImplementedError(
            f"rig {rig.get('name')!r}: chamber driver {driver!r} is not wired yet "
            "(only the simulated rig 'sim' is)")
    from drivers.geometry import angles_for_reference
    from simulators.rig import connect_rig, start_sim_rig

    kwargs: dict[str, Any] = {"seed": seed, **(sim_options or {})}
    if faults is not None:
        kwargs["faults"] = faults
    async with start_sim_rig(clock, **kwargs) as sim:
        chamber, turntable, accel = await _maybe_await(connect_rig(sim, clock))
        n_axes = turntable.n_axes
        try:
            yield RigDevices(chamber, turntable, accel,
                             lambda ref: tuple(angles_for_reference(np.asarray(ref), n_axes)))
        finally:
            for dev in (chamber, turntable, accel):
                # Modbus drivers close through their link; the serial bridge directly.
                owner = dev if hasattr(dev, "close") else getattr(dev, "link", None)
                if owner is not None and hasattr(owner, "close"):
                    await _maybe_await(owner.close())


async def _maybe_await(v: Any) -> Any:
    import inspect

    return await v if inspect.isawaitable(v) else v
