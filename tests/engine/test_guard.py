"""Faults decided once by the guard: transient ones retried, configuration ones fail at once."""

from __future__ import annotations

from typing import Any

import pytest

from drivers.clock import VirtualClock
from drivers.faults import (
    ConnectionLost,
    DeviceFault,
    DeviceTimeout,
    ExceptionReply,
    ModbusExceptionReply,
    ValueOutOfRange,
)
from service.engine.guard import (
    AbortRequested,
    CampaignFailed,
    DeviceGuard,
    FaultPolicy,
    classify,
)


class Device:
    """Raises the given faults in turn, then answers 42."""

    def __init__(self, *faults: Exception) -> None:
        self.faults = list(faults)
        self.calls = 0

    async def __call__(self) -> int:
        self.calls += 1
        if self.faults:
            raise self.faults.pop(0)
        return 42


def guard(clock: Any, **policy: Any) -> tuple[DeviceGuard, list[str]]:
    events: list[str] = []
    g = DeviceGuard(clock, FaultPolicy(**policy), on_suspend=lambda r: events.append("suspend"),
                    on_resume=lambda: events.append("resume"))
    return g, events


@pytest.mark.parametrize("code", [1, 2, 3])
async def test_modbus_illegal_function_address_value_fail_on_first_occurrence(code: int) -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    g, events = guard(clock)
    dev = Device(ModbusExceptionReply("chamber", f"write register 2: exception code {code}",
                                      code, 2))
    with pytest.raises(CampaignFailed, match=r"chamber.set_setpoint: chamber: write register 2.*"
                                             r"fix: "):
        await g.call("chamber.set_setpoint", dev)
    assert dev.calls == 1 and g.faults_retried == 0 and events == []


async def test_bridge_refusal_fails_at_once_but_busy_and_garbled_are_retried() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    g, _ = guard(clock)
    refused = Device(ExceptionReply("sensor", "n must be 1..100000", 3))
    with pytest.raises(CampaignFailed, match="samples_per_position"):
        await g.call("accelerometer.acquire", refused)
    assert refused.calls == 1
    busy = Device(ExceptionReply("sensor", "busy", 6), ExceptionReply("sensor", "bad frame", 2))
    assert await g.call("accelerometer.acquire", busy) == 42
    assert busy.calls == 3


async def test_transient_faults_retried_with_backoff_on_the_clock() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    g, events = guard(clock, retry_attempts=4, retry_backoff_s=1.0)
    dev = Device(DeviceTimeout("table", "no reply"), ConnectionLost("table", "dropped"),
                 ModbusExceptionReply("table", "busy", 6, 100))
    t0 = clock.now()
    assert await g.call("turntable.read_status", dev) == 42
    assert clock.now() - t0 == pytest.approx(1.0 + 2.0 + 4.0)
    assert g.faults_retried == 3 and events == []


async def test_suspend_limit_counts_real_outage_time_not_sped_up_time() -> None:
    """At 3000× a 1,800 s limit must mean 1,800 real seconds = 5.4e6 clock seconds."""

    class Scaled(VirtualClock):
        factor = 3000.0

    clock = Scaled(idle_wall_s=0.0)
    g, events = guard(clock, retry_attempts=2, retry_backoff_s=1.0, suspend_poll_s=30.0,
                      suspend_limit_s=1800.0)
    dev = Device(*[DeviceTimeout("chamber", "no reply")] * 50)  # 50 × 30 s real = 25 min
    assert await g.call("chamber.read_status", dev) == 42
    assert events == ["suspend", "resume"]
    dead = Device(*[DeviceTimeout("chamber", "no reply")] * 1000)
    with pytest.raises(CampaignFailed, match="1800 s of real time"):
        await g.call("chamber.read_status", dead)
    assert dead.calls == 2 + 60  # 1800 s / 30 s polls, real time


async def test_abort_is_honoured_before_the_next_device_call() -> None:
    clock = VirtualClock(idle_wall_s=0.0)
    asked = {"abort": False}
    g = DeviceGuard(clock, FaultPolicy(), lambda r: None, lambda: None,
                    check_abort=lambda: asked["abort"])
    dev = Device()
    assert await g.call("x", dev) == 42
    asked["abort"] = True
    with pytest.raises(AbortRequested):
        await g.call("x", dev)
    assert dev.calls == 1


def test_classification_table() -> None:
    assert classify(ValueOutOfRange("chamber", "setpoint 400 °C"))[0] == "configuration"
    assert classify(ModbusExceptionReply("chamber", "x", 6, 1))[0] == "transient"
    assert classify(DeviceTimeout("chamber", "x"))[0] == "transient"
    assert classify(DeviceFault("chamber", "x"))[0] == "transient"
