"""Device calls with retry, suspension and a suspend limit: the engine's one retry owner,
and its one hold loop (:func:`hold`), which every suspender uses.

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
* a device the campaign can go on without (one sensor of several, while
  another still reads) is given up instead (``give_up``): its configuration
  fault, or a transient one that outlasts the retries, drops that sensor
  (service/engine/sensors.py); the last sensor left suspends like any device.
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
from service.engine.suspenders import Suspender

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

    async def call(self, label: str, fn: Callable[[], Awaitable[T]], *,
                   give_up: Callable[[str], Exception] | None = None) -> T:
        """``await fn()`` with the fault policy; ``label`` names the call in messages.

        ``give_up``: a device the campaign can go on without (one sensor of several):
        a configuration fault, or a transient one that outlasts the retries, raises
        ``give_up(reason)`` instead of failing or suspending the campaign.
        """
        if self.check_abort():
            raise AbortRequested(label)
        last: DeviceFault | None = None
        delay_s = self.policy.retry_backoff_s
        for _ in range(max(1, self.policy.retry_attempts)):
            self.calls += 1
            try:
                return await fn()
            except DeviceFault as exc:
                self._fail_if_configuration(label, exc, give_up)
                last = exc
                self.faults_retried += 1
                await self.clock.sleep(delay_s)
                delay_s *= 2.0
                if self.check_abort():
                    raise AbortRequested(label) from exc
        assert last is not None
        if give_up is not None:
            raise give_up(f"{label}: no answer after {self.policy.retry_attempts} tries "
                          f"(last fault: {last})") from last
        return await self._suspended(label, fn, last)

    def _fail_if_configuration(self, label: str, fault: DeviceFault,
                               give_up: Callable[[str], Exception] | None = None) -> None:
        kind, fix = classify(fault)
        if kind != "configuration":
            return
        if give_up is not None:
            raise give_up(f"{label}: {fault}") from fault
        raise CampaignFailed(f"{label}: {fault} (configuration fault, not retried; "
                             f"fix: {fix})") from fault

    async def _suspended(self, label: str, fn: Callable[[], Awaitable[T]],
                         fault: DeviceFault) -> T:
        """The device suspender: :func:`hold` until ``fn`` answers, called again every
        ``suspend_poll_s`` of real time (a sped-up clock must not hammer a dead device)."""
        self.suspensions += 1
        answer: list[T] = []
        last = [fault]

        async def still_failing() -> str | None:
            self.calls += 1
            try:
                answer.append(await fn())
            except DeviceFault as exc:
                self._fail_if_configuration(label, exc)
                last[0] = exc
                return f"{label}: {exc}"
            return None

        async def abort_point() -> None:
            if self.check_abort():
                raise AbortRequested(label)

        limit_s = self.policy.suspend_limit_s
        await hold(self.clock, Suspender("device", restart_soak=False, clear_s=0.0,
                                         limit_s=limit_s),
                   f"{label}: {fault}", still_failing,
                   poll_s=self.policy.suspend_poll_s * clock_speed(self.clock),
                   checkpoint=abort_point, wait=self.clock.sleep,
                   on_hold=self.on_suspend, on_clear=lambda _since_s: self.on_resume(),
                   limit_text=lambda _why: (f"{label}: device did not recover within "
                                            f"{limit_s:.0f} s of real time (last fault: "
                                            f"{last[0]})"))
        return answer[0]


async def hold(clock: Clock, susp: Suspender, why: str,
               still_tripped: Callable[[], Awaitable[str | None]], *, poll_s: float,
               checkpoint: Callable[[], Awaitable[None]],
               wait: Callable[[float], Awaitable[None]],
               on_hold: Callable[[str], None], on_clear: Callable[[float], None],
               paused_s: Callable[[], float] = lambda: 0.0,
               limit_text: Callable[[str], str] | None = None) -> None:
    """The engine's one hold loop: suspended until ``still_tripped()`` has said None for
    ``susp.clear_s`` (a device fault, a chamber out of band or in alarm, a table that
    missed its position).

    Every round: the limit (``susp.limit_s`` of real time held, the clock's time over
    its speed-up, time paused by the operator (``paused_s``) excluded: then
    :class:`CampaignFailed`), a ``checkpoint`` (pause and abort), a ``wait`` of
    ``poll_s`` and a look (``still_tripped``: None when clear, else why not).
    ``on_hold(why)`` once at the start; ``on_clear(since_s)`` once cleared.
    """
    since_s = clock.now()
    paused0_s = paused_s()
    clear_since_s: float | None = None
    on_hold(why)
    while True:
        held_s = clock.now() - since_s - (paused_s() - paused0_s)
        if held_s / clock_speed(clock) >= susp.limit_s:
            raise CampaignFailed(limit_text(why) if limit_text is not None else
                                 f"{why}; not cleared within {susp.limit_s:.0f} s of real time")
        await checkpoint()
        if poll_s > 0:
            await wait(poll_s)
        now_why = await still_tripped()
        if now_why is not None:
            why, clear_since_s = now_why, None
            continue
        if clear_since_s is None:
            clear_since_s = clock.now()
        if clock.now() - clear_since_s >= susp.clear_s:
            on_clear(since_s)
            return
