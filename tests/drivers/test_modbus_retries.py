"""The Modbus link retries each idempotent request, not the composite read around it.

A chamber status read on the Watlow F4T (cascade) map is five requests. With 20 % of
requests refused (DEVICE BUSY, seeded) a five-request read fails two times in three
unless each request is retried on its own; a fault that does not heal still reaches
the caller, saying how often it was tried. A write that triggers an action (the
table's move command) is sent again only when the device answered DEVICE BUSY.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator
from dataclasses import dataclass

import numpy as np
import pytest

from drivers.chamber import ModbusChamber
from drivers.clock import VirtualClock
from drivers.faults import ConnectionLost, DeviceFault, ExceptionReply
from drivers.modbus_link import ModbusLink, RetryPolicy
from drivers.registermaps import CHAMBER_MAPS, SOAKCAL_TABLE
from drivers.turntable import ModbusTurntable
from simulators.chamber_sim import ChamberPhysics, ChamberRegisterImage
from simulators.faults import SimFaults
from simulators.modbus_server import ModbusSimServer, start_modbus_server
from simulators.turntable_sim import TurntablePhysics, TurntableRegisterImage

RETRYING = RetryPolicy(timeout_s=0.15)  # the shipped tries (3 per read / idempotent write)
NO_RETRY = RetryPolicy(timeout_s=0.15, read_attempts=1, write_attempts=1)
# Where the test counts requests exactly, a connect or reply must not time out on a loaded
# machine (seen: a 0.15-s connect lost under load made one of the three tries no request).
PATIENT = RetryPolicy(timeout_s=5.0)
F4T = CHAMBER_MAPS["watlow-f4t-cascade"]  # PV, SP, WSP, ramp and power: five requests


@dataclass
class Twin:
    clock: VirtualClock
    faults: SimFaults
    server: ModbusSimServer


@pytest.fixture
async def chamber_twin() -> AsyncIterator[Twin]:
    clock = VirtualClock()
    faults = SimFaults()
    rng = np.random.default_rng(18)  # the fault draws: the same in every run
    physics = ChamberPhysics(clock, np.random.default_rng(1), faults=faults)
    server = await start_modbus_server(ChamberRegisterImage(physics, F4T), faults,
                                       rng)
    yield Twin(clock, faults, server)
    await server.stop()


@pytest.fixture
async def table_twin() -> AsyncIterator[Twin]:
    clock = VirtualClock()
    faults = SimFaults()
    physics = TurntablePhysics(clock, faults=faults)
    server = await start_modbus_server(TurntableRegisterImage(physics, SOAKCAL_TABLE), faults,
                                       np.random.default_rng(18))
    yield Twin(clock, faults, server)
    await server.stop()


async def _status_reads(twin: Twin, policy: RetryPolicy, n: int) -> tuple[int, ModbusChamber]:
    """How many of ``n`` status reads fail under the twin's faults."""
    ch = ModbusChamber(ModbusLink(twin.server.url, twin.clock, device="chamber", policy=policy),
                       F4T)
    failed = 0
    for _ in range(n):
        try:
            st = await ch.read_status()
        except DeviceFault:
            failed += 1
        else:
            assert st.process_c == pytest.approx(23.0, abs=0.3)
    await ch.close()
    return failed, ch


async def test_status_read_is_five_requests(chamber_twin: Twin) -> None:
    _, ch = await _status_reads(chamber_twin, RETRYING, 1)
    assert ch.link.stats["requests"] == 5  # what makes a whole-read retry hopeless


async def test_composite_read_completes_under_twenty_percent_faults(chamber_twin: Twin) -> None:
    chamber_twin.faults.p_exception = 0.2
    failed, ch = await _status_reads(chamber_twin, RETRYING, 30)
    # Per request 0.2³ = 0.8 %, per read 3.9 %: about one failure in 30 reads, not 20
    # (P(more than 5) < 0.2 % for a binomial(30, 0.039)).
    assert failed <= 5, failed
    assert ch.link.stats["retries"] >= 15, ch.link.stats  # ≈ 0.2 × 150 requests were refused


async def test_without_per_request_retries_most_composite_reads_fail(chamber_twin: Twin) -> None:
    # The same faults and reads, one try per request: 1 − 0.8⁵ = 67 % of reads fail
    # (P(fewer than 12 of 30) < 0.1 %).
    chamber_twin.faults.p_exception = 0.2
    failed, ch = await _status_reads(chamber_twin, NO_RETRY, 30)
    assert failed >= 12, failed
    assert ch.link.stats["retries"] == 0


async def test_lost_replies_of_a_read_are_retried(chamber_twin: Twin) -> None:
    # Replies swallowed (the client times out) or the connection closed instead of a reply.
    chamber_twin.faults.p_no_reply = 0.1
    chamber_twin.faults.p_drop = 0.1
    failed, ch = await _status_reads(chamber_twin, RETRYING, 8)
    assert failed <= 2, failed  # per read 3.4 %: P(3 or more of 8) < 0.5 %
    assert ch.link.stats["retries"] >= 3 and ch.link.stats["reconnects"] >= 1, ch.link.stats


async def test_persistent_fault_surfaces_with_its_tries(chamber_twin: Twin) -> None:
    chamber_twin.faults.p_exception = 1.0
    ch = ModbusChamber(ModbusLink(chamber_twin.server.url, chamber_twin.clock, device="chamber",
                                  policy=PATIENT), F4T)
    with pytest.raises(ExceptionReply) as err:
        await ch.read_status()
    assert err.value.code == 6
    first = min(f.address for f in F4T.fields())
    assert str(err.value) == (f"chamber: read register {first}: exception code 6 "
                              "(SERVER DEVICE BUSY) (3 tries)")
    assert ch.link.stats["requests"] == 3 and ch.link.stats["retries"] == 2
    await ch.close()


async def test_setpoint_write_is_retried_after_a_lost_reply(chamber_twin: Twin) -> None:
    # p_drop closes the connection *after* the controller applied the write: writing the
    # same setpoint again is harmless, so the driver marks it idempotent and the link retries.
    ch = ModbusChamber(ModbusLink(chamber_twin.server.url, chamber_twin.clock, device="chamber",
                                  policy=RETRYING), F4T)
    chamber_twin.faults.p_drop = 0.3
    for sp in (10.0, -20.0, 35.0, 5.0):
        await ch.set_setpoint(sp)
    chamber_twin.faults.p_drop = 0.0
    assert (await ch.read_status()).setpoint_c == 5.0
    assert ch.link.stats["retries"] >= 1
    await ch.close()


async def test_move_command_is_resent_only_when_the_table_did_not_act(table_twin: Twin) -> None:
    tt = ModbusTurntable(ModbusLink(table_twin.server.url, table_twin.clock, device="turntable",
                                    policy=RETRYING), SOAKCAL_TABLE)
    table_twin.faults.p_exception = 1.0
    with pytest.raises(ExceptionReply, match=r"\(3 tries\)"):
        await tt.move_to((0.0, 90.0, 0.0))  # the targets (a level) are tried three times
    assert tt.link.stats["requests"] == 3
    write_field = tt.link.write_field
    fault = {"p_exception": 1.0}

    async def faulty_command(f, value, *, idempotent=False):  # type: ignore[no-untyped-def]
        for name, p in fault.items():  # the targets went through; now the command's fault
            setattr(table_twin.faults, name, p)
        await write_field(f, value, idempotent=idempotent)

    tt.link.write_field = faulty_command  # type: ignore[method-assign]
    # DEVICE BUSY: the table says it did not act, so the command is sent again.
    table_twin.faults.p_exception = 0.0
    tt.link.stats["requests"] = 0
    with pytest.raises(ExceptionReply, match=r"\(3 tries\)") as err:
        await tt.move_to((0.0, 90.0, 0.0))
    assert err.value.code == 6 and tt.link.stats["requests"] == 1 + 3
    # The connection closed instead of a reply: the table may be moving; not repeated.
    fault = {"p_exception": 0.0, "p_drop": 1.0}
    table_twin.faults.p_exception = 0.0
    tt.link.stats["requests"] = 0
    with pytest.raises(ConnectionLost) as lost:
        await tt.move_to((0.0, 90.0, 0.0))
    assert "tries" not in str(lost.value)
    assert tt.link.stats["requests"] == 1 + 1  # one targets write, one command
    table_twin.faults.p_drop = 0.0
    await tt.close()


async def test_a_closed_connection_is_not_waited_out(chamber_twin: Twin) -> None:
    # The device closes the connection instead of replying: pymodbus alone would wait the
    # whole reply timeout (5 s here) per try; the link gives up on the request at once.
    chamber_twin.faults.p_drop = 1.0
    link = ModbusLink(chamber_twin.server.url, chamber_twin.clock, device="chamber",
                      policy=RetryPolicy(timeout_s=5.0))
    t0 = time.perf_counter()
    with pytest.raises(ConnectionLost, match=r"closed the connection \(3 tries\)"):
        await link.read_registers(F4T.process_c.address, 2)
    assert time.perf_counter() - t0 < 2.5  # three tries: a reconnect each, no 5-s timeout
    assert link.stats["requests"] == 3
    chamber_twin.faults.p_drop = 0.0
    assert len(await link.read_registers(F4T.process_c.address, 2)) == 2
    await link.close()
