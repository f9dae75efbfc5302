"""The rig's safe state: every device parks itself, each under its own timeout.

As OpenHTF's plugs tear themselves down, each device of a rig owns its safe
state (``park`` in drivers/protocols.py): the chamber goes to its map's
``[safe] setpoint_c`` (or a campaign's ``safe_c``) and is stopped where the map
says ``[safe] stop = true``; the table is stopped and sent to its map's
``[safe] angles_deg`` (home); a hand-placed fixture has nothing to move and
says so. Sensors have no safe state: nothing is sent to them.

:func:`park_rig` is the engine's one way to park (the runner's ``finally``
calls it). Each device parks as its own task, so one device's failure or hang
never keeps another from parking. Each try is bounded by a wall-clock timeout
(:func:`asyncio.timeout`, the event loop's time): a hung device is a socket
without a reply, and the injected clock is no measure of that (a VirtualClock
jumps ahead while a reply is in flight; the Modbus link's reply timeout is
wall time for the same reason). Between tries the park waits on the injected
clock, with back-off. A device whose park finds the rig lease lost
(``LeaseLost``, service/engine/fencing.py) is not tried again: the rig is
another process's.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

from drivers.clock import Clock
from service.engine.rigs import RigDevices
from service.engine.store import LeaseLost

PARK_ATTEMPTS = 3  # tries of one device's park
PARK_BACKOFF_S = 1.0  # clock s before the second try; doubled before each next
# Wall s per try: a Modbus park is two or three writes of at most 1 s each (the link's
# reply timeout, drivers/modbus_link.py) plus a lease confirmation per write.
PARK_TIMEOUT_S = 10.0
LEASE_LOST_REPORT = "not sent: lease lost"
PARKED_DEVICES = ("chamber", "turntable")  # the report's keys, in this order


def parked(outcome: str) -> bool:
    """A report line that says the device reached its safe state."""
    return outcome == "ok" or outcome.startswith("ok: ")


async def park_rig(devices: RigDevices, clock: Clock, *, safe_c: float | None = None,
                   timeout_s: float = PARK_TIMEOUT_S) -> dict[str, str]:
    """Park every device of the rig; returns one line per device, keys :data:`PARKED_DEVICES`.

    A line reads ``"ok: <what the device did>"`` (``"ok: setpoint 23 °C, controller
    stopped"``), ``"not sent: lease lost"``, ``"no device"``, or ``"failed after 3
    tries: <the last error>"``. ``safe_c`` overrides the chamber's own safe setpoint.
    Never raises for a device's failure; a cancellation is passed on (callers that
    must park through a cancel shield this call).
    """
    chamber, turntable = devices.chamber, devices.turntable
    parks: dict[str, Callable[[], Awaitable[str]] | None] = {
        "chamber": None if chamber is None else (lambda: chamber.park(safe_c)),
        "turntable": None if turntable is None else turntable.park,
    }
    outcomes = await asyncio.gather(*(_park_one(park, clock, timeout_s)
                                      for park in parks.values()))
    return dict(zip(parks, outcomes, strict=True))


async def _park_one(park: Callable[[], Awaitable[str]] | None, clock: Clock,
                    timeout_s: float) -> str:
    if park is None:
        return "no device"
    delay_s = PARK_BACKOFF_S
    last = ""
    for attempt in range(1, PARK_ATTEMPTS + 1):
        limit = asyncio.timeout(timeout_s)
        try:
            async with limit:
                done = await park()
            return f"ok: {done}" if done else "ok"
        except LeaseLost:
            return LEASE_LOST_REPORT
        except Exception as exc:  # noqa: BLE001 - any failure: keep it for the report, retry
            # The limit's own TimeoutError, not one the device raised itself.
            last = (f"no answer within {timeout_s:g} s" if limit.expired()
                    else f"{type(exc).__name__}: {exc}")
        if attempt < PARK_ATTEMPTS:
            await clock.sleep(delay_s)
            delay_s *= 2.0
    return f"failed after {PARK_ATTEMPTS} tries: {last}"
