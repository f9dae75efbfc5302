"""Fenced devices: a process that cannot confirm its rig lease sends the rig nothing.

The rig lease (service/engine/manager.py) decides which process drives a rig,
and every measurement commit checks it in its own transaction
(:func:`service.engine.store.commit_measurements`). That fences the *rows*.
The devices need the same fence: a process stalled past its lease (SIGSTOP, a
swapped-out VM, a debugger) that resumes must not move the table or change
the setpoint under the process that took the rig over — its shielded park
included, which would otherwise send the table home in the middle of the new
holder's measurement.

:func:`fence_devices` wraps a rig's chamber, turntable and sensors so that every
command that changes the rig (setpoint, ramp rate, run, stop, move, sensor
configuration) first confirms the lease with ``confirm()``; a lease lost, or
one that cannot be confirmed (the database does not answer), raises
:class:`service.engine.store.LeaseLost` and the command is not sent. Reads
(status, acquisitions, identity) pass through unchecked: they change nothing.
A device's ``park`` (service/engine/park.py) is such a command, so a process
without the lease parks nothing.

The confirmation returns when the lease ends, and the wall clock is read again
once the database has answered: a process stopped after the answer resumes past
that end and sends nothing.

A command is often several writes (a table move is the targets, then the move
command; a park is a setpoint, a stop, a move). A stall between two of them
would leave the rest unfenced, so the fence is also put at the link level: a
Modbus device's :class:`drivers.modbus_link.ModbusLink` confirms the lease
before *every write request* it sends, each retry included (``before_write``).
One request per command was the other way, and it does not work in general: the
shipped table map keeps its targets (200–205) and its command (210) apart, and
Modbus does not promise that a device applies one multi-register write in address
order. Devices without a Modbus link (the sensor bridge, a hand-placed table,
test fakes) are fenced per command only. The devices carry no fencing token
themselves (a register map has no place for one), so what stays uncovered is a
stall between a write's last clock reading and its bytes leaving the socket.

The rows have their fence too: :func:`service.engine.store.fenced_sessions`.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import functools
import logging
from collections.abc import Callable
from typing import Any

from service.db.timestamps import utcnow
from service.engine.rigs import RigDevices
from service.engine.store import LeaseLost

log = logging.getLogger(__name__)
# Returns when the lease held ends (UTC; None: not known); raises LeaseLost when not held.
ConfirmLease = Callable[[], dt.datetime | None]

# The commands of each device protocol (drivers/protocols.py) that change the rig.
CHAMBER_COMMANDS = frozenset({"set_setpoint", "set_ramp_rate", "run", "stop", "park"})
TURNTABLE_COMMANDS = frozenset({"move_to", "stop", "home", "park"})
SENSOR_COMMANDS = frozenset({"configure"})


class FencedDevice:
    """One device whose commands (``commands``) wait for ``confirm()``; all else delegates."""

    def __init__(self, device: Any, name: str, commands: frozenset[str],
                 confirm: ConfirmLease) -> None:
        self._device = device
        self._name = name
        self._commands = commands
        self._confirm = confirm

    def __getattr__(self, attr: str) -> Any:
        value = getattr(self._device, attr)
        if attr not in self._commands or not callable(value):
            return value

        async def fenced(*args: Any, **kwargs: Any) -> Any:
            _confirm(self._confirm, f"{self._name}.{attr}")
            return await value(*args, **kwargs)

        return fenced


def _confirm(confirm: ConfirmLease, command: str) -> None:
    try:
        until = confirm()
    except LeaseLost as exc:
        raise LeaseLost(f"{command} not sent: {exc}") from exc
    except Exception as exc:  # the database does not answer: the lease is not confirmed
        raise LeaseLost(f"{command} not sent: lease not confirmed "
                        f"({type(exc).__name__}: {exc})") from exc
    # Read the wall clock again, after the database answered: a process stopped between
    # that answer and here (seen: SIGSTOP right after a commit) resumes past its lease's
    # end, and another process may hold the rig by then.
    if until is not None and utcnow() >= until:
        raise LeaseLost(f"{command} not sent: the lease ended at {until.isoformat()} "
                        "while it was being confirmed")


def fence_devices(devices: RigDevices, confirm: ConfirmLease) -> RigDevices:
    """``devices`` with every rig-changing command behind ``confirm()``, and every write
    request of a Modbus device's link too (see the module doc; the links are the
    devices' own, so this sets their ``before_write`` for as long as they live)."""
    def wrap(dev: Any, name: str, commands: frozenset[str]) -> Any:
        if dev is None:
            return None
        link = getattr(dev, "link", None)
        if hasattr(link, "before_write"):
            link.before_write = functools.partial(_confirm, confirm)
        return FencedDevice(dev, name, commands, confirm)

    return dataclasses.replace(
        devices,
        chamber=wrap(devices.chamber, "chamber", CHAMBER_COMMANDS),
        turntable=wrap(devices.turntable, "turntable", TURNTABLE_COMMANDS),
        accelerometer=wrap(devices.accelerometer, "accelerometer", SENSOR_COMMANDS),
        accelerometers={serial: wrap(acc, f"accelerometer {serial}", SENSOR_COMMANDS)
                        for serial, acc in devices.accelerometers.items()},
    )
