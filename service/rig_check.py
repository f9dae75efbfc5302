"""``soakcal rig check``: is every device of a rig there, the right one, and answering sanely?

Connects to the chamber, the turntable and the sensor of one rig (through the
same drivers a campaign uses, ``service.engine.rigs.open_rig``), reads
identity, process values and status, compares the chamber's PV with the
sensors' die temperatures (``service.rig_plausibility``: a mis-scaled map is
named with the key that fixes it), and moves nothing unless ``move`` is asked:
then a setpoint nudge at a commanded ramp whose working setpoint is watched,
and one table move, each put back. Every check is ``pass``, ``fail`` (with what
to fix) or ``skip`` (with why: e.g. the map has no identity register because
the manual documents none). The rig passes when no check fails.
docs/rig-check.md describes every check.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import sys
from collections.abc import Awaitable, Callable
from dataclasses import asdict, dataclass
from typing import Any, Literal

from drivers.clock import Clock, RealClock, ScaledClock
from drivers.faults import DeviceFault, ModbusExceptionReply
from service import rig_plausibility as plausibility

Status = Literal["pass", "fail", "skip"]

TABLE_STEP_DEG = 5.0  # one table move on the outer axis, deg
ANGLE_TOLERANCE_DEG = 0.1
MOVE_TIMEOUT_S = 120.0  # rig time for one table move to report in-position
G_BAND = (0.9, 1.1)  # |mean specific force| of a static sensor, g
SENSOR_SAMPLES = 16
EXPECTED_MODEL = "ADXL355"
#: ADXL355 identification registers 0x00-0x02 (datasheet): what a bridge reporting
#: part ids must read. Bridges whose ID reply carries no part ids are not judged on them.
ADXL355_IDS = {"devid_ad": 0xAD, "devid_mst": 0x1D, "partid": 0xED}


@dataclass(frozen=True)
class Check:
    device: str  # chamber, turntable, sensor
    check: str  # connect, identity, status, alarms, setpoint_nudge, table_move, acquire
    status: Status
    detail: str
    fix: str = ""


class _Recorder:
    def __init__(self) -> None:
        self.checks: list[Check] = []

    def add(self, device: str, check: str, status: Status, detail: str, fix: str = "") -> bool:
        self.checks.append(Check(device, check, status, detail, fix))
        return status != "fail"

    async def guard(self, device: str, check: str, fix: str,
                    body: Callable[[], Awaitable[bool]]) -> bool:
        """Run one check; a device fault is that check's failure, not a crash of the rest."""
        try:
            return await body()
        except DeviceFault as fault:
            return self.add(device, check, "fail", f"no usable answer: {fault}", fix)


_CONNECT_FIX = ("check the URL, cabling, Modbus unit id (device_id) and the controller's "
                "comms settings (baud, parity, protocol)")


def passed(checks: list[Check]) -> bool:
    return all(c.status != "fail" for c in checks)


async def check_rig(rig: dict[str, Any], *, move: bool = False,
                    clock: Clock | None = None) -> list[Check]:
    """All checks of one rig config (a ``rigs`` row as a dict)."""
    from service.engine.rigs import RigConfigError, open_rig, rig_time_scale

    if clock is None:
        scale = rig_time_scale(rig)
        # A sim rig runs in this process: fast simulated time keeps a table move short.
        clock = ScaledClock(600.0) if scale is None else (
            RealClock() if scale == 1.0 else ScaledClock(scale))
    rec = _Recorder()
    channels = _first_entry_channels(rig)
    try:
        async with open_rig(rig, clock, serials=list(channels.values())) as devices:
            chamber_ok = await _check_chamber(rec, devices.chamber, rig)
            await _check_table(rec, devices.turntable, move, clock)
            dies_c: list[float] = []
            if not channels:
                dies_c += await _check_sensor(rec, devices.accelerometer, rig)
            # A multiplexing bridge: every channel is a sensor, checked as "sensor @<ch>"
            # against the serial its channel declares.
            accels = devices.accelerometers or {s: devices.accelerometer
                                                for s in channels.values()}
            for ch, serial in channels.items():
                dies_c += await _check_sensor(rec, accels[serial], rig, device=f"sensor @{ch}",
                                              expected_serial=serial, blank_ok=True)
            if chamber_ok:
                plausible = await rec.guard(
                    "chamber", "pv_vs_die", _CONNECT_FIX,
                    lambda: plausibility.check_pv_against_die(rec, devices.chamber, dies_c))
                if not move:
                    rec.add("chamber", "setpoint_nudge", "skip", "not asked (--move)")
                elif not plausible:
                    rec.add("chamber", "setpoint_nudge", "skip",
                            "not nudged: the PV is not plausible, so a setpoint written "
                            "through this map would not be the temperature asked")
                else:
                    await rec.guard("chamber", "setpoint_nudge", _CONNECT_FIX,
                                    lambda: plausibility.nudge_and_ramp(rec, devices.chamber,
                                                                        rig, clock))
    except RigConfigError as exc:
        rec.add("rig", "config", "fail", str(exc), "fix the rig config (PUT /api/v1/rigs/NAME)")
    return rec.checks


# --- chamber ---------------------------------------------------------------------------


async def _identity(rec: _Recorder, device: str, driver: Any) -> bool:
    regmap = driver.regmap
    ident = regmap.identity
    if ident is None:
        # Still proves the device answers; a refused register is the status check's to name.
        with contextlib.suppress(ModbusExceptionReply):
            await driver.read_status()
        rec.add(device, "connect", "pass", f"answers at {driver.link.url}")
        rec.add(device, "identity", "skip",
                f"map {regmap.name} has no identity register (none documented)")
        return await _map_checks(rec, device, driver)
    got = await driver.read_identity()
    rec.add(device, "connect", "pass", f"answers at {driver.link.url}")
    if got != ident.expect:
        return rec.add(
            device, "identity", "fail",
            f"register {ident.register} reads {_number(got)}, map {regmap.name} expects "
            f"{_number(ident.expect)}",
            "another device answers at this URL/unit id, or the rig names the wrong map")
    rec.add(device, "identity", "pass",
            f"register {ident.register} = {_number(got)} as map {regmap.name} expects")
    return await _map_checks(rec, device, driver)


def _number(value: float | None) -> str:
    """A register value as the manual prints it: 8126464, not 8.12646e+06."""
    if value is None:
        return "nothing"
    if math.isfinite(value) and value == int(value):
        return str(int(value))
    return f"{value:.6g}"


async def _map_checks(rec: _Recorder, device: str, driver: Any) -> bool:
    """The map's own ``[[checks]]``: registers that must read a given value.

    A wrong setting (say °F display units) is reported, and the device's
    remaining checks still run: it is the right device, set up wrongly.
    """
    for c in driver.regmap.checks:
        got = await driver.link.read_field(c.field)
        if not c.accepts(got):
            rec.add(device, f"register:{c.register}", "fail",
                    f"{c.register} reads {_number(got)}, map {driver.regmap.name} expects "
                    f"{c.wanted()} ({c.what})", c.fix or "set it on the controller")
        else:
            rec.add(device, f"register:{c.register}", "pass", c.what)
    return True


async def _check_chamber(rec: _Recorder, chamber: Any, rig: dict[str, Any]) -> bool:
    """Identity, status and alarms; ``False`` when the chamber cannot be read at all."""
    if hasattr(chamber, "rig_checks"):  # a driver that checks its own controller (ESPEC)
        if not await rec.guard("chamber", "connect", getattr(chamber, "connect_fix", _CONNECT_FIX),
                               lambda: _driver_checks(rec, chamber, rig)):
            return False
    elif not hasattr(chamber, "regmap"):  # not a map-driven driver: nothing to compare against
        rec.add("chamber", "identity", "skip", "driver has no register map")
    elif not await rec.guard("chamber", "connect", _CONNECT_FIX,
                             lambda: _identity(rec, "chamber", chamber)):
        return False
    lo, hi = plausibility.usable_range_c(chamber, rig)

    async def status() -> bool:
        st = await chamber.read_status()
        wsp = ("no WSP register" if st.working_setpoint_c is None
               else f"WSP {st.working_setpoint_c:.1f} °C")
        ramp = ("no ramp register (steps)" if not _has_ramp(chamber)
                else f"ramp {st.ramp_c_per_min:g} °C/min")
        detail = (f"PV {st.process_c:.1f} °C, SP {st.setpoint_c:.1f} °C, {wsp}, {ramp}, "
                  f"{'running' if st.running else 'stopped'}")
        ok = math.isfinite(st.process_c) and lo - 30.0 <= st.process_c <= hi + 30.0
        rec.add("chamber", "status", "pass" if ok else "fail", detail,
                "" if ok else "the PV is implausible: check the map's scale and word order "
                "and the controller's units (the pv_vs_die check names the likely cause)")
        if st.alarms:
            rec.add("chamber", "alarms", "fail", "active: " + ", ".join(st.alarms),
                    "clear the alarm at the controller before a campaign")
        else:
            rec.add("chamber", "alarms", "pass", "none active")
        await plausibility.check_mode(rec, chamber)
        return True

    try:
        return await status()
    except DeviceFault as fault:
        silent = await plausibility.silent_registers(chamber)
        if silent:
            rec.add("chamber", "status", "fail", "; ".join(d for d, _ in silent), silent[0][1])
        else:
            rec.add("chamber", "status", "fail", f"no usable answer: {fault}", _CONNECT_FIX)
        return False


async def _driver_checks(rec: _Recorder, chamber: Any, rig: dict[str, Any]) -> bool:
    """The checks a map-less driver makes of its own controller (``rig_checks``)."""
    for check, status, detail, fix in await chamber.rig_checks(
            plausibility.usable_range_c(chamber, rig)):
        rec.add("chamber", check, status, detail, fix)
    return True


def _has_ramp(chamber: Any) -> bool:
    """The chamber has a ramp to set: a map-less driver says so (``has_static_ramp``), else
    is taken to have one."""
    regmap = getattr(chamber, "regmap", None)
    if regmap is None:
        return bool(getattr(chamber, "has_static_ramp", True))
    return regmap.ramp_field() is not None


# --- turntable -------------------------------------------------------------------------


def _table_driver(table: Any) -> Any:
    """The map-driven driver of a table: itself, or the motor of a hand-axis stage
    (``drivers.manual_table.HandAxisTurntable``); ``None`` for a table without a map."""
    if hasattr(table, "regmap"):
        return table
    motor = getattr(table, "motor", None)
    return motor if hasattr(motor, "regmap") else None


def _angles_text(table: Any, driver: Any, angles_deg: tuple[float, ...]) -> str:
    """The status' angles, saying which are read back and which are not: a map without a
    position readback reports the commanded angles; a hand axis is set by the operator."""
    regmap = getattr(driver, "regmap", None)
    read_back = regmap is None or getattr(regmap, "position_deg", True) is not None
    motor = ", ".join(f"{a:.2f}" for a in angles_deg[: getattr(driver, "n_axes", None)])
    how = "read back" if read_back else (
        f"commanded, not read back: map {regmap.name} has no position readback")
    if driver is not None and driver is not table:  # the motor of a hand-axis stage
        hand = angles_deg[-1]
        return (f"motor ({motor})° ({how}), hand axis {hand:.2f}° (set by hand, not read; "
                "asked only in a campaign)")
    if regmap is None:
        return f"angles ({motor})°"
    return f"angles ({motor})° ({how})"


async def _check_table(rec: _Recorder, table: Any, move: bool, clock: Clock) -> None:
    driver = _table_driver(table)
    if driver is not None and not await rec.guard("turntable", "connect", _CONNECT_FIX,
                                                  lambda: _identity(rec, "turntable", driver)):
        return

    async def status() -> bool:
        st = await table.read_status()
        detail = (f"{_angles_text(table, driver, tuple(st.angles_deg))}, "
                  f"{'in position' if st.in_position else 'not in position'}"
                  f"{', moving' if st.moving else ''}")
        if st.faults:
            return rec.add("turntable", "status", "fail",
                           detail + "; faults: " + ", ".join(st.faults),
                           "clear the table's fault (limit switch, encoder, following error)")
        ok = rec.add("turntable", "status", "pass", detail)
        _check_homed(rec, driver, st.homed)
        return ok

    if not await rec.guard("turntable", "status", _CONNECT_FIX, status):
        return
    if not move:
        rec.add("turntable", "table_move", "skip", "not asked (--move)")
        return

    async def one_move() -> bool:
        st0 = await table.read_status()
        if st0.moving:  # someone else commands the table: moving it now would fight them
            return rec.add("turntable", "table_move", "fail", "the table is moving already",
                           "wait until nothing else commands the table, then check again")
        start = tuple(st0.angles_deg)
        limit = getattr(getattr(driver, "regmap", None), "range_deg", 720.0)
        step = TABLE_STEP_DEG if start[0] + TABLE_STEP_DEG <= limit else -TABLE_STEP_DEG
        target = (start[0] + step, *start[1:])
        for goal in (target, start):
            await table.move_to(goal)
            reached = await _wait_in_position(table, goal, clock)
            if reached is not None:
                return rec.add("turntable", "table_move", "fail", reached,
                               "check the drives are enabled and nothing blocks the table")
        regmap = getattr(driver, "regmap", None)
        unread = "" if regmap is None or regmap.position_deg is not None else (
            f" (commanded angles: map {regmap.name} has no position readback, so only the "
            "drive's in-position report is checked, not where the axis stopped)")
        return rec.add("turntable", "table_move", "pass",
                       f"axis 0 {start[0]:.2f}° → {target[0]:.2f}° → {start[0]:.2f}°{unread}")

    await rec.guard("turntable", "table_move", _CONNECT_FIX, one_move)


def _check_homed(rec: _Recorder, driver: Any, homed: bool | None) -> None:
    """The map's ``homed`` status: a table not homed counts its angles from wherever it
    stood at power-up, so every reference direction of a campaign would be wrong."""
    regmap = getattr(driver, "regmap", None)
    if homed is None or regmap is None or getattr(regmap, "homed_bit", None) is None:
        return
    if homed:
        rec.add("turntable", "homed", "pass", "every axis reports homed")
        return
    fix = ("home every axis before a campaign: the map's [[sequence.home]] starts it "
           "(drivers/turntable.py home(); no soakcal command runs it yet), or home at the "
           "drive (its homing input or the vendor's software); then check again"
           if "home" in regmap.sequences else
           "home every axis at the drive before a campaign (its homing input or the "
           f"vendor's software: map {regmap.name} has no [[sequence.home]]); then check again")
    rec.add("turntable", "homed", "fail",
            "not homed: the angles count from where the table stood at power-up, so the "
            "references a campaign labels would not be where gravity is", fix)


async def _wait_in_position(table: Any, goal: tuple[float, ...], clock: Clock) -> str | None:
    """``None`` once in position at ``goal``; else what went wrong."""
    t0 = clock.now()
    await clock.sleep(0.2)  # let the table latch the command before the first poll
    while clock.now() - t0 < MOVE_TIMEOUT_S:
        st = await table.read_status()
        if st.faults:
            return "faults during the move: " + ", ".join(st.faults)
        if st.in_position and not st.moving:
            err = max(abs(a - g) for a, g in zip(st.angles_deg, goal, strict=False))
            if err > ANGLE_TOLERANCE_DEG:
                return (f"in position at ({', '.join(f'{a:.3f}' for a in st.angles_deg)})°, "
                        f"asked ({', '.join(f'{g:.3f}' for g in goal)})°: {err:.3f}° off")
            return None
        await clock.sleep(0.5)
    return f"not in position within {MOVE_TIMEOUT_S:g} s of rig time"


# --- sensor ----------------------------------------------------------------------------


def _first_entry_channels(rig: dict[str, Any]) -> dict[int, str]:
    """``sensors[0].channels`` as ``{channel: serial}`` in channel order (``{}``: one sensor)."""
    sensors = rig.get("sensors") or [{}]
    table = sensors[0].get("channels") if isinstance(sensors[0], dict) else None
    if not isinstance(table, dict) or not table:
        return {}
    try:
        return {int(k): str(v).strip() for k, v in sorted(table.items(), key=lambda kv: int(kv[0]))}
    except ValueError:
        return {}  # open_rig names the bad key (RigConfigError)


async def _check_sensor(rec: _Recorder, accel: Any, rig: dict[str, Any], *,
                        device: str = "sensor", expected_serial: str | None = None,
                        blank_ok: bool = False) -> list[float]:
    """Identity and one static reading of one sensor; ``blank_ok``: a blank fixture EEPROM
    is not a mismatch (a channel bound by the rig's table, checked at campaign start).

    Returns the die temperature it read (``[]`` when none), for the chamber's PV check."""
    dies_c: list[float] = []
    sensors = rig.get("sensors") or [{}]
    if expected_serial is None and isinstance(sensors[0], dict):
        expected_serial = sensors[0].get("serial")
    fix = "check the sensor bridge's port (URL), baud rate and that its firmware answers ID"

    async def identity() -> bool:
        ident = await accel.identify()
        detail = f"model {ident.model}, serial {ident.serial}, firmware {ident.firmware}"
        if not str(ident.model).upper().startswith(EXPECTED_MODEL):
            return rec.add(device, "identity", "fail",
                           f"{detail}: model {ident.model}, expected {EXPECTED_MODEL}",
                           "another device answers on this port")
        reported = {k: getattr(ident, k, None) for k in ADXL355_IDS}
        wrong = [f"{k} 0x{v:02X} (expected 0x{ADXL355_IDS[k]:02X})"
                 for k, v in reported.items() if v is not None and v != ADXL355_IDS[k]]
        if wrong:
            return rec.add(device, "identity", "fail", f"{detail}: " + ", ".join(wrong),
                           "the part behind the bridge is not an ADXL355, or its SPI "
                           "wiring is wrong")
        if all(v is not None for v in reported.values()):
            detail += ", part ids " + " ".join(f"0x{v:02X}" for v in reported.values())
        else:
            detail += " (the bridge reports no part ids)"
        if blank_ok and expected_serial and not ident.serial:
            detail += f" (fixture EEPROM blank: {expected_serial} not checked here)"
        elif expected_serial and ident.serial != expected_serial:
            return rec.add(device, "identity", "fail",
                           f"serial {ident.serial} connected, rig config names "
                           f"{expected_serial}", "mount the named sensor or fix the rig config")
        return rec.add(device, "identity", "pass", detail)

    if not await rec.guard(device, "identity", fix, identity):
        return dies_c

    async def acquire() -> bool:
        acq = await accel.acquire(SENSOR_SAMPLES)
        if math.isfinite(acq.sensor_c):
            dies_c.append(acq.sensor_c)
        g = math.sqrt(sum(v * v for v in acq.mean_g))
        detail = (f"{acq.n} samples: |g| {g:.4f} g, die {acq.sensor_c:.1f} °C, "
                  f"sd {max(acq.sd_g) * 1e6:.0f} µg")
        if acq.saturated:
            return rec.add(device, "acquire", "fail", detail + ", saturated",
                           "the sensor is being shaken or its range is too small")
        if not G_BAND[0] <= g <= G_BAND[1]:
            cause, fix = _g_cause(g)
            return rec.add(device, "acquire", "fail",
                           f"{detail}: outside {G_BAND[0]}…{G_BAND[1]} g of local gravity{cause}",
                           fix)
        return rec.add(device, "acquire", "pass", detail)

    await rec.guard(device, "acquire", fix, acquire)
    return dies_c


#: A static sensor reads 1 g; these factors are what a units or range mix-up makes of it.
G_MISREADINGS = (
    (9.80665, " — it reads in m/s², not g",
     "the bridge reports m/s²: set its output to g (or divide by 9.80665 in its config)"),
    (2.0, " — ×2: the range setting and the scale the driver assumes disagree",
     "set the same range (±2/±4/±8 g) on the sensor and in the rig's sensor config"),
    (4.0, " — ×4: the range setting and the scale the driver assumes disagree",
     "set the same range (±2/±4/±8 g) on the sensor and in the rig's sensor config"),
    (0.5, " — ×0.5: the range setting and the scale the driver assumes disagree",
     "set the same range (±2/±4/±8 g) on the sensor and in the rig's sensor config"),
    (0.25, " — ×0.25: the range setting and the scale the driver assumes disagree",
     "set the same range (±2/±4/±8 g) on the sensor and in the rig's sensor config"),
)


def _g_cause(g: float) -> tuple[str, str]:
    """The misreading that explains |g| (within 5 %), else the sensor is not at rest."""
    for factor, cause, fix in G_MISREADINGS:
        if abs(g / factor - 1.0) <= 0.05:
            return cause, fix
    return "", "the sensor must rest static; check its mounting and range setting"


# --- CLI -------------------------------------------------------------------------------


def add_parser(sub: Any) -> None:
    """``soakcal rig check NAME [--move] [--json]`` (registered by service/cli.py)."""
    rig = sub.add_parser("rig", help="rig tools (connection check)")
    rig_sub = rig.add_subparsers(dest="rig_command", metavar="ACTION", required=True)
    check = rig_sub.add_parser(
        "check", help="connect to every device of a rig and report each check")
    check.add_argument("name", metavar="NAME", help="rig name (GET /api/v1/rigs)")
    check.add_argument("--move", action="store_true",
                       help="also nudge the setpoint by 0.5 °C and move the table 5°, then back")
    check.add_argument("--json", action="store_true", help="print the checks as JSON")
    check.set_defaults(handler=run_check_cli)
    validate = rig_sub.add_parser(
        "validate", help="check a register map file (chamber or turntable) without a device")
    validate.add_argument("map", metavar="MAP.toml",
                          help="a map file, or the name of a shipped map")
    validate.set_defaults(handler=run_validate_cli)
    from service.cli_ops import add_rig_admin_parsers

    add_rig_admin_parsers(rig_sub)


def run_validate_cli(args: argparse.Namespace) -> int:
    """``soakcal rig validate MAP.toml``: "OK: <what it describes>" or exit 2 naming the key."""
    from drivers.registermaps import MapError, describe_map, load_map

    try:
        regmap = load_map(args.map)
    except MapError as exc:
        print(f"soakcal rig validate: {exc}", file=sys.stderr)
        return 2
    print(f"OK: {describe_map(regmap)}")
    return 0


def run_check_cli(args: argparse.Namespace) -> int:
    from sqlalchemy import make_url, select
    from sqlalchemy.exc import SQLAlchemyError

    from service.campaigns import rig_busy, seed_sim_rig
    from service.config import resolve_database_url
    from service.db.models import Rig
    from service.db.session import make_session_factory, session_scope, upgrade_database

    url = resolve_database_url()
    try:
        upgrade_database(url)
        factory = make_session_factory(url)
        try:
            with session_scope(factory) as session:
                seed_sim_rig(session)  # a fresh install has the sim rig before any `serve`
                row = session.scalar(select(Rig).where(Rig.name == args.name))
                known = session.scalars(select(Rig.name).order_by(Rig.name)).all()
                busy = row is not None and rig_busy(session, row.name)
                rig = None if row is None else {
                    "name": row.name, "chamber": row.chamber or {},
                    "turntable": row.turntable or {}, "sensors": row.sensors or []}
        finally:
            factory.kw["bind"].dispose()
    except SQLAlchemyError as exc:
        where = make_url(url).render_as_string(hide_password=True)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"soakcal rig check: cannot read rigs from {where}: {first}", file=sys.stderr)
        return 1
    if rig is None:
        print(f"soakcal rig check: no rig named {args.name!r} (known: "
              f"{', '.join(known) or 'none'})", file=sys.stderr)
        return 2
    if busy:  # as REST answers 409: the campaign owns the devices (a --move would nudge a soak)
        print(f"soakcal rig check: rig {args.name!r} runs a campaign now: its devices are in "
              "use; check it once the campaign has finished", file=sys.stderr)
        return 2
    checks = asyncio.run(check_rig(rig, move=args.move))
    if args.json:
        print(json.dumps(report(args.name, checks), indent=2))
    else:
        print(format_report(args.name, checks))
    return 0 if passed(checks) else 1


def report(name: str, checks: list[Check]) -> dict[str, Any]:
    """The JSON shape shared by ``--json`` and ``POST /api/v1/rigs/{name}/check``."""
    return {"rig": name, "passed": passed(checks), "checks": [asdict(c) for c in checks]}


def format_report(name: str, checks: list[Check]) -> str:
    lines = [f"rig {name}:"]
    for c in checks:
        lines.append(f"  {c.status.upper():4}  {c.device:9} {c.check:15} {c.detail}")
        if c.fix:
            lines.append(f"        fix: {c.fix}")
    n_fail = sum(c.status == "fail" for c in checks)
    lines.append(f"{'PASS' if not n_fail else 'FAIL'}: {len(checks)} checks, {n_fail} failed")
    return "\n".join(lines)
