"""``soakcal sim``: run a simulated rig on loopback ports until interrupted.

The lead wires :func:`run_sim` into ``service/cli.py``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys

from drivers.clock import RealClock, ScaledClock
from drivers.registermaps import MapError, load_chamber_map, load_turntable_map, shipped_maps
from simulators.chamber_sim import ControllerSetup
from simulators.faults import SimFaults
from simulators.pty_link import open_pty_link
from simulators.rig import RigFaults, SimRig, start_sim_rig


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="soakcal sim",
        description="Start a simulated rig (chamber, turntable, sensor bridge) on loopback.",
    )
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default loopback)")
    p.add_argument("--port", type=int, default=0,
                   help="base port: chamber, +1 table, +2 sensor (default 0 = ephemeral)")
    p.add_argument("--chamber-map", default="eurotherm3216", metavar="NAME|FILE",
                   help="chamber register map: a shipped name (" + ", ".join(shipped_maps())
                   + ") or a map file (docs/registers.md); default eurotherm3216")
    p.add_argument("--table-map", default="soakcal-table", metavar="NAME|FILE",
                   help="turntable register map (default soakcal-table)")
    p.add_argument("--seed", type=int, default=1, help="sensor truth and noise seed")
    p.add_argument("--speed", type=float, default=1.0,
                   help="simulated seconds per wall second (1 = real time)")
    p.add_argument("--die-tau-s", type=float, default=None,
                   help="die lag behind chamber air, s (default: the twin's, else 900)")
    p.add_argument("--twin", metavar="FILE", default=None,
                   help="twin or model JSON (soakcal twin fit / diagnose --write-twin): the "
                        "simulated sensor, its noise and die lag")
    p.add_argument("--p-exception", type=float, default=0.0,
                   help="probability of an exception reply per request (all devices)")
    p.add_argument("--p-no-reply", type=float, default=0.0,
                   help="probability of a swallowed reply per request (all devices)")
    p.add_argument("--p-drop", type=float, default=0.0,
                   help="probability of a dropped connection per request (all devices)")
    p.add_argument("--stuck-pv", action="store_true", help="chamber PV frozen")
    p.add_argument("--never-in-position", action="store_true",
                   help="table never reports in-position")
    # The chamber controller set up unlike its map, as controllers are found in labs:
    # `soakcal rig check NAME --move` against it must fail naming the cause.
    ctl = p.add_argument_group("controller setup (docs/rig-check.md, physical plausibility)")
    ctl.add_argument("--decimals", type=int, default=None, metavar="N",
                     help="decimal places of integer temperature registers (default: the map's)")
    ctl.add_argument("--units", choices=("C", "F"), default="C",
                     help="temperature units the controller serves (default C)")
    ctl.add_argument("--ramp-per", choices=("min", "hour"), default="min",
                     help="time unit of the ramp register (default min)")
    ctl.add_argument("--swap-words", action="store_true",
                     help="32-bit values in the opposite word order to the map's")
    ctl.add_argument("--silent", action="append", default=[], metavar="REGISTER",
                     help="a register (map name) that answers 'illegal address'; repeatable")
    ctl.add_argument("--mode", choices=("auto", "manual", "standby"), default="auto",
                     help="the controller's mode (default auto)")
    ctl.add_argument("--hold", action="append", default=[], metavar="REGISTER=VALUE",
                     help="a value the controller holds in a register of the map (instead of "
                          "what its [[checks]] expect), e.g. loop_mode=54; repeatable")
    ctl.add_argument("--profile-owns-setpoint", default=None, metavar="REGISTER=VALUE",
                     help="a profile runs and owns the setpoint (a Watlow F4): setpoint writes "
                          "are not followed until REGISTER is written VALUE, e.g. "
                          "terminate_profile=1")
    ctl.add_argument("--single-writes-only", action="store_true",
                     help="multiple-register writes (FC 16) are acknowledged but not executed "
                          "(a CSZ EZT-430i)")
    p.add_argument("--serial", action="store_true",
                   help="also expose each simulated sensor bridge on a pseudo-terminal "
                        "(/dev/pts/N) that a serial reader opens like a USB-serial port")
    p.add_argument("--duration-s", type=float, default=None,
                   help="stop after this many wall seconds (default: run until Ctrl-C)")
    return p


def run_sim(argv: list[str] | None = None) -> int:
    """Entry point; returns a process exit code."""
    args = build_parser().parse_args(argv)
    try:  # a bad map is bad input: one line naming the file and key, exit 2
        load_chamber_map(args.chamber_map)
        load_turntable_map(args.table_map)
    except MapError as exc:
        print(f"soakcal sim: {exc}", file=sys.stderr)
        return 2
    chamber_regs = load_chamber_map(args.chamber_map).registers
    unknown = [r for r in args.silent if r not in chamber_regs]
    if unknown:
        print(f"soakcal sim: --silent {unknown[0]}: map {args.chamber_map} names no such "
              f"register (it has {', '.join(chamber_regs)})", file=sys.stderr)
        return 2
    holds = []
    for item in args.hold:
        name, _, value = item.partition("=")
        try:
            holds.append((name, float(value)))
        except ValueError:
            print(f"soakcal sim: --hold {item}: expected REGISTER=NUMBER", file=sys.stderr)
            return 2
        if name not in chamber_regs:
            print(f"soakcal sim: --hold {item}: map {args.chamber_map} names no register "
                  f"{name!r}", file=sys.stderr)
            return 2
    args.holds = tuple(holds)
    args.profile = None
    if args.profile_owns_setpoint is not None:
        name, _, value = args.profile_owns_setpoint.partition("=")
        try:
            args.profile = (name, float(value))
        except ValueError:
            print(f"soakcal sim: --profile-owns-setpoint {args.profile_owns_setpoint}: expected "
                  "REGISTER=NUMBER", file=sys.stderr)
            return 2
        if name not in chamber_regs:
            print(f"soakcal sim: --profile-owns-setpoint: map {args.chamber_map} names no "
                  f"register {name!r}", file=sys.stderr)
            return 2
    if args.decimals is not None and not 0 <= args.decimals <= 4:
        print(f"soakcal sim: --decimals {args.decimals}: expected 0…4", file=sys.stderr)
        return 2
    args.truth = None
    if args.twin:
        from calibration.discrepancy.twin_file import load_model_or_twin
        from calibration.errors import CalibrationError
        from simulators.truth import SensorTruth

        try:
            twin = load_model_or_twin(args.twin)
            args.truth = SensorTruth.from_twin(twin)
        except (CalibrationError, ValueError) as exc:
            print(f"soakcal sim: {exc}", file=sys.stderr)
            return 2
        if args.die_tau_s is None and twin.die_tau_s is not None:
            args.die_tau_s = twin.die_tau_s
    if args.die_tau_s is None:
        args.die_tau_s = 900.0
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(_serve(args))
    return 0


def describe(rig: SimRig, ptys: list[str] | None = None) -> str:
    """How to reach each device (printed at start); ``ptys``: the ``--serial`` ports."""
    c_host, c_port = rig.chamber_server.host, rig.chamber_server.port
    m = load_chamber_map(rig.chamber_map)
    ports = [f"  sensor   serial {path}  (pseudo-terminal: open it as a serial port, any "
             "baud rate; docs/sensor-bridge.md)" for path in ptys or []]
    return "\n".join([
        "soakcal simulated rig",
        f"  chamber  modbus {rig.chamber_url}  map={rig.chamber_map}  device_id={m.unit_id} "
        f"(PV holding reg {m.process_c.address}, SP {m.setpoint_c.address})",
        f"  table    modbus {rig.table_url}  map={rig.table_map}  axes={rig.table.n_axes}"
        + _table_units(rig.table_map),
        f"  sensor   serial {rig.sensor_url}  (pyserial serial_for_url; docs/sensor-bridge.md)",
        *ports,
        "  example:",
        "    python -c \"import asyncio; from pymodbus.client import AsyncModbusTcpClient as C\n"
        f"    async def m():\n      c = C('{c_host}', port={c_port}); await c.connect()\n"
        f"      print((await c.read_holding_registers({m.process_c.address}, "
        f"count={m.process_c.n_registers}, device_id=1)).registers)\n"
        "    asyncio.run(m())\"",
        "  Ctrl-C to stop.",
    ])


async def _serve(args: argparse.Namespace) -> None:
    def f() -> SimFaults:
        return SimFaults(p_exception=args.p_exception, p_no_reply=args.p_no_reply,
                         p_drop=args.p_drop)

    faults = RigFaults(chamber=f(), table=f(), sensor=f())
    faults.chamber.stuck_process_value = args.stuck_pv
    faults.table.never_in_position = args.never_in_position
    clock = RealClock() if args.speed == 1.0 else ScaledClock(args.speed)
    controller = ControllerSetup(decimals=args.decimals, units=args.units,
                                 ramp_per=args.ramp_per, swap_words=args.swap_words,
                                 silent=frozenset(args.silent), mode=args.mode,
                                 holds=getattr(args, "holds", ()),
                                 profile_owns_setpoint=getattr(args, "profile", None),
                                 single_writes_only=args.single_writes_only)
    async with start_sim_rig(clock, seed=args.seed, truth=args.truth,
                             chamber_map=args.chamber_map,
                             faults=faults, ports=args.port, host=args.host,
                             die_tau_s=args.die_tau_s, table_map=args.table_map,
                             controller=controller) as rig:
        links = [await open_pty_link(rig.bridge_server.host, rig.bridge_server.port)
                 ] if args.serial else []
        try:
            if links:
                print(describe(rig, [link.path for link in links]), flush=True)
            else:
                print(describe(rig), flush=True)
            stop = asyncio.Event()
            if args.duration_s is not None:
                asyncio.get_running_loop().call_later(args.duration_s, stop.set)
            with contextlib.suppress(asyncio.CancelledError):
                await stop.wait()
        finally:
            for link in links:
                await link.close()


def _table_units(table_map: str) -> str:
    """``  unit ids 1/2`` for a drive per axis (the map's ``[axes] unit_ids``), else ``""``."""
    units = load_turntable_map(table_map).unit_ids
    return "  unit ids " + "/".join(str(u) for u in units) if units else ""
