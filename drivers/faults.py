"""Fault taxonomy shared by all drivers; the engine maps each kind to retry, suspend or fail.

Drivers raise, they do not decide: the campaign engine's
:class:`service.engine.guard.DeviceGuard` decides what a call's fault means (the Modbus
link only repeats one idempotent request a few times first, drivers/modbus_link.py). ``retryable``
says whether waiting can heal the fault (a timeout, a dropped connection, a
busy device) or whether it is a configuration fault that fails the campaign
at once (a register the device does not have, a value it refuses).
"""

from __future__ import annotations

# Modbus exception codes (Modbus Application Protocol v1.1b3, section 7).
MODBUS_EXCEPTION_NAMES = {
    1: "ILLEGAL FUNCTION",
    2: "ILLEGAL DATA ADDRESS",
    3: "ILLEGAL DATA VALUE",
    4: "SERVER DEVICE FAILURE",
    5: "ACKNOWLEDGE",
    6: "SERVER DEVICE BUSY",
    10: "GATEWAY PATH UNAVAILABLE",
    11: "GATEWAY TARGET FAILED TO RESPOND",
}
# Codes that describe the request, not the device's momentary state: retrying cannot help.
MODBUS_CONFIGURATION_CODES = frozenset({1, 2, 3})


class DeviceFault(Exception):
    """Base class: something went wrong talking to a device. ``device`` names it."""

    retryable: bool = True

    def __init__(self, device: str, message: str) -> None:
        super().__init__(f"{device}: {message}")
        self.device = device
        self.message = message


class DeviceTimeout(DeviceFault):
    """No reply within the timeout."""


class ConnectionLost(DeviceFault):
    """Transport closed or refused; the driver will try to reconnect on the next call."""


class ExceptionReply(DeviceFault):
    """The device answered with a protocol exception (e.g. a bridge ``ERR`` line).

    Whether it heals depends on the protocol's code; the engine's guard
    classifies it (service/engine/guard.py). Modbus replies use the subclass
    :class:`ModbusExceptionReply`, which knows its codes.
    """

    def __init__(self, device: str, message: str, code: int | None = None) -> None:
        super().__init__(device, message)
        self.code = code


class ModbusExceptionReply(ExceptionReply):
    """A Modbus exception response; codes 1-3 are configuration faults (not retryable).

    ``address`` is the first register of the refused request.
    """

    def __init__(self, device: str, message: str, code: int | None = None,
                 address: int | None = None) -> None:
        super().__init__(device, message, code)
        self.address = address
        self.retryable = code not in MODBUS_CONFIGURATION_CODES


class ValueOutOfRange(DeviceFault):
    """A value to write or a value read is outside what the device or its map allows."""

    retryable = False


class ProtocolError(DeviceFault):
    """Malformed frame, bad checksum, unexpected reply."""


class ConfigurationFault(ExceptionReply):
    """The device permanently refuses the request (unknown command, argument it never accepts).

    Retrying cannot help: the rig or campaign configuration must change, so the
    engine fails the campaign at once instead of suspending on it.
    """

    retryable = False
