"""Device calls with retry, suspension and a suspend limit: the engine's one retry owner.

Every device call of the engine goes through :meth:`DeviceGuard.call`, and
each fault is decided once, here (drivers raise; the Modbus link only repeats one
idempotent request a few times first, see drivers/modbus_link.py):

* :func:`classify` sorts a fault into *transient* (timeouts, dropped
  connections, DEVICE BUSY, a garbled frame: retried with exponential
  back-off on the injected clock, ``retry_attempts`` tries) or
  *configuration* (Modbus ILLEGAL FUNCTION/ADDRESS/VALUE, a value out of range,
  a sensor bridge's ``ERR 1``/``ERR 3`` refusal): the campaign fails on the
  first occurrence, with the device, the register or parameter, and the fix.
* a transient fault that outlasts the retries *suspends* the campaign: it stays
  ``running`` with ``suspended_reason`` set (``on_suspend``) and the call is
  retried every ``suspend_poll_s`` until the device answers (``on_resume``),
  like a bluesky suspender.
* suspended for longer than ``suspend_limit_s`` of **real** outage time:
  :class:`CampaignFailed`. Real time is the clock's time divided by its speed-up
  (``ScaledClock.factor``); a sped-up twin at 3000× would otherwise turn the
  1,800 s limit into 0.6 s of wall time, less than one Modbus timeout.
* an operator abort is honoured before every device call (``check_abort``), so a
  pending abort waits for at most one device call, whatever the phase.

Anything a device layer raises that is not a :class:`DeviceFault` (say a
``UnicodeError`` from a decoder) is not caught here: it propagates to the
engine, which fails the campaign and drives the rig to its safe state.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Literal, TypeVar

from drivers.clock import Clock
from drivers.faults import (
    DeviceFault,
    ExceptionReply,
    ModbusExceptionReply,
    ValueOutOfRange,
)

T = TypeVar("T")
FaultClass = Literal["transient", "configuration"]

# Sensor bridge ERR codes (docs/sensor-bridge.md): 1 unknown command, 2 bad frame or
# checksum (line noise: transient), 3 bad argument, 6 busy (transient).
BRIDGE_CONFIGURATION_CODES = frozenset({1, 3})
_MODBUS_FIXES = {
    1: "the controller does not implement this function: check the rig's chamber/table 'map'",
    2: "the register does not exist on this controller: check the rig's register map "
       "(docs/registers.md) and device_id",
    3: "the controller refused the value: check the campaign's setpoints, ramp rate and the "
       "rig's chamber range",
}


class CampaignFailed(Exception):
    """The campaign cannot continue; the message goes to ``campaign.error``."""


class AbortRequested(Exception):
    """Raised out of a wait when the operator asked to abort (handled by the engine)."""


def classify(fault: DeviceFault) -> tuple[FaultClass, str]:
    """(class, fix) of a device fault: the one table of what heals by waiting."""
    if isinstance(fault, ModbusExceptionReply):
        if fault.retryable:
            return "transient", ""
        return "configuration", _MODBUS_FIXES.get(fault.code or 0, "check the rig config")
    if isinstance(fault, ExceptionReply):  # the sensor bridge's ERR <code> <text>
        if fault.code in BRIDGE_CONFIGURATION_CODES:
            return "configuration", (
                "the sensor bridge refused the command: check the campaign's "
                "samples_per_position, range_g and odr_hz against docs/sensor-bridge.md")
        if not fault.retryable:  # ConfigurationFault, SensorMismatch: refused for good
            return "configuration", "the device refuses this for good: fix what the message names"
        return "transient", ""
    if isinstance(fault, ValueOutOfRange) or not fault.retryable:
        return "configuration", "a value is outside what the device accepts: check the campaign"
    return "transient", ""


@dataclass
class FaultPolicy:
    retry_attempts: int = 4
    retry_backoff_s: float = 1.0
    suspend_poll_s: float = 30.0
    suspend_limit_s: float = 1800.0  # real (wall) outage time


def clock_speed(clock: Clock) -> float:
    """How many clock seconds pass per real second (1 for real and virtual clocks)."""
    return float(getattr(clock, "factor", 1.0) or 1.0)


class DeviceGuard:
    """Wraps device coroutines; counts faults for the steps log and tests."""

    def __init__(
        self,
        clock: Clock,
        policy: FaultPolicy,
        on_suspend: Callable[[str], None],
        on_resume: Callable[[], None],
        check_abort: Callable[[], bool] = lambda: False,
    ) -> None:
        self.clock = clock
        self.policy = policy
        self.on_suspend = on_suspend
        self.on_resume = on_resume
        self.check_abort = check_abort
        self.faults_retried = 0
        self.suspensions = 0
        self.calls = 0

    async def call(self, label: str, fn: Callable[[], Awaitable[T]]) -> T:
        """``await fn()`` with the fault policy; ``label`` names the call in messages."""
        if self.check_abort():
            raise AbortRequested(label)
        last: DeviceFault | None = None
        delay_s = self.policy.retry_backoff_s
        for _ in range(max(1, self.policy.retry_attempts)):
            self.calls += 1
            try:
                return await fn()
            except DeviceFault as exc:
                self._fail_if_configuration(label, exc)
                last = exc
                self.faults_retried += 1
                await self.clock.sleep(delay_s)
                delay_s *= 2.0
                if self.check_abort():
                    raise AbortRequested(label) from exc
        assert last is not None
        return await self._suspended(label, fn, last)

    def _fail_if_configuration(self, label: str, fault: DeviceFault) -> None:
        kind, fix = classify(fault)
        if kind == "configuration":
            raise CampaignFailed(f"{label}: {fault} (configuration fault, not retried; "
                                 f"fix: {fix})") from fault

    async def _suspended(self, label: str, fn: Callable[[], Awaitable[T]],
                         fault: DeviceFault) -> T:
        self.suspensions += 1
        since_s = self.clock.now()
        speed = clock_speed(self.clock)
        self.on_suspend(f"{label}: {fault}")
        while True:
            if self.check_abort():
                raise AbortRequested(label)
            outage_real_s = (self.clock.now() - since_s) / speed
            if outage_real_s >= self.policy.suspend_limit_s:
                raise CampaignFailed(
                    f"{label}: device did not recover within {self.policy.suspend_limit_s:.0f} s "
                    f"of real time (last fault: {fault})"
                )
            # Poll in real seconds too: a sped-up clock must not hammer a dead device.
            await self.clock.sleep(self.policy.suspend_poll_s * speed)
            self.calls += 1
            try:
                result = await fn()
            except DeviceFault as exc:
                self._fail_if_configuration(label, exc)
                fault = exc
                continue
            self.on_resume()
            return result
