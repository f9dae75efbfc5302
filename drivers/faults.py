"""Fault taxonomy shared by all drivers; the engine maps each kind to retry, suspend or abort."""

from __future__ import annotations


class DeviceFault(Exception):
    """Base class: something went wrong talking to a device. ``device`` names it."""

    retryable: bool = True

    def __init__(self, device: str, message: str) -> None:
        super().__init__(f"{device}: {message}")
        self.device = device
        self.message = message


class DeviceTimeout(DeviceFault):
    """No reply within the timeout (after the driver's own retries)."""


class ConnectionLost(DeviceFault):
    """Transport closed or refused; the driver will try to reconnect on the next call."""


class ExceptionReply(DeviceFault):
    """The device answered with a protocol exception (e.g. Modbus exception code)."""

    def __init__(self, device: str, message: str, code: int | None = None) -> None:
        super().__init__(device, message)
        self.code = code


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
