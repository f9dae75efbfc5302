"""A chamber's safe state, whatever its protocol (:meth:`drivers.protocols.Chamber.park`).

The setpoint goes to the one asked for, else the chamber's own safe setpoint (a map's
``[safe] setpoint_c``, an ESPEC rig's ``safe_setpoint_c``); a target beyond the
chamber's range goes to the range's edge (a park must not be refused) and the report
says so; then, where the chamber is told to (``stop_when_safe``), it is stopped.
"""

from __future__ import annotations

from typing import Any


async def park_chamber(chamber: Any, setpoint_c: float | None, *, stopped: str) -> str:
    """Park ``chamber`` and return what was done, in words; ``stopped``: how its stop reads
    ("controller stopped", "controller in standby")."""
    asked_c = chamber.safe_setpoint_c if setpoint_c is None else float(setpoint_c)
    lo_c, hi_c = chamber.range_c
    target_c = min(max(asked_c, lo_c), hi_c)
    await chamber.set_setpoint(target_c)
    done = f"setpoint {target_c:g} °C"
    if target_c != asked_c:
        done += f" (the range's edge; {asked_c:g} °C asked)"
    if chamber.stop_when_safe:
        await chamber.stop()
        done += f", {stopped}"
    return done
