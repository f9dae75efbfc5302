"""``soakcal sensor id|bind|read URL``: talk to one sensor bridge directly (docs/sensor-bridge.md).

For the bench, before a rig is configured: who is on this port, write the
sensor's serial into its fixture EEPROM (the binding step), take one averaged
reading. ``URL`` is anything pyserial opens (``/dev/ttyACM0``,
``socket://127.0.0.1:PORT`` for ``soakcal sim``'s bridge). Exit 0 on success,
1 when the device fails or is not an ADXL355, 2 on bad input.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from typing import Any

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


def add_parser(sub: Any) -> None:
    sensor = sub.add_parser("sensor", help="identify, bind or read one sensor bridge")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("url", metavar="URL", help="serial port or pyserial URL of the bridge")
    common.add_argument("--framing", choices=("v2", "v1"), default="v2",
                        help="bridge framing (v1: XOR bridges in the field; default v2)")
    common.add_argument("--baudrate", type=int, default=115200, help="bit/s (default 115200)")
    common.add_argument("--timeout", type=float, default=2.0, metavar="S",
                        help="reply timeout per line in s (default 2)")
    common.add_argument("--protocol", choices=("bridge", "stream"), default="bridge",
                        help="framed bridge (default) or a plain x,y,z,t line stream")
    common.add_argument("--units", choices=("g", "mg", "m/s2"), default="g",
                        help="stream only: acceleration unit of the lines (default g)")
    common.add_argument("--columns", default="x,y,z,t", metavar="ORDER",
                        help="stream only: order of the four values (default x,y,z,t)")
    common.add_argument("--channel", type=int, default=None, metavar="CH",
                        help="the sensor on channel CH (0..99) of a multiplexing bridge; "
                             "omitted: the unaddressed commands (a one-sensor bridge, or "
                             "channel 0)")
    actions = sensor.add_subparsers(dest="sensor_command", metavar="ACTION", required=True)
    ident = actions.add_parser("id", parents=[common], help="print the bridge's identity")
    ident.add_argument("--json", action="store_true", help="one JSON object")
    ident.set_defaults(handler=_run_id)
    bind = actions.add_parser("bind", parents=[common],
                              help="write SERIAL into the fixture EEPROM and read it back")
    bind.add_argument("serial", metavar="SERIAL")
    bind.set_defaults(handler=_run_bind)
    read = actions.add_parser("read", parents=[common], help="one averaged reading")
    read.add_argument("-n", "--samples", type=int, default=100, help="samples (default 100)")
    read.set_defaults(handler=_run_read)


#: Config key paths of drivers.sensor_config → the option that sets them.
_OPTION_FOR_KEY = {"--.url": "URL", "--.baudrate": "--baudrate", "--.stream.columns": "--columns"}


def _link(args: argparse.Namespace) -> Any:
    """The options as a sensor link config (same validation as a rig's sensors[0])."""
    from drivers.sensor_config import parse_sensor_config

    return parse_sensor_config({
        "url": args.url, "baudrate": args.baudrate, "protocol": args.protocol,
        "framing": args.framing, "serial_binding": "any",
        "stream": {"units": args.units, "columns": args.columns.split(",")}}, "--")


def _accel(args: argparse.Namespace) -> Any:
    from drivers.clock import RealClock

    link = _link(args)
    if link.protocol == "stream":
        from drivers.stream_sensor import StreamingAccelerometer

        return StreamingAccelerometer(link.url, RealClock(), fmt=link.stream,
                                      baudrate=link.baudrate, timeout_s=args.timeout)
    from drivers.sensor_bridge import SerialAccelerometer

    return SerialAccelerometer(link.url, RealClock(), framing=link.framing,
                               baudrate=link.baudrate, timeout_s=args.timeout,
                               channel=args.channel)


def _run(args: argparse.Namespace, body: Any) -> int:
    from drivers.faults import DeviceFault
    from drivers.sensor_config import SensorConfigError

    try:
        _link(args)
    except SensorConfigError as exc:
        key, _, why = str(exc).partition(": ")
        print(f"soakcal sensor: {_OPTION_FOR_KEY.get(key, key)}: {why}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.channel is not None:
        from drivers.bridge_protocol import MAX_CHANNEL

        if args.protocol == "stream" or not 0 <= args.channel <= MAX_CHANNEL:
            print(f"soakcal sensor: --channel: expected 0..{MAX_CHANNEL} on a framed bridge "
                  f"(a plain stream has no channels)", file=sys.stderr)
            return EXIT_BAD_INPUT
    if args.sensor_command == "bind" and args.protocol == "stream":
        print("soakcal sensor bind: a plain stream has no fixture EEPROM to write",
              file=sys.stderr)
        return EXIT_BAD_INPUT

    async def go() -> int:
        accel = _accel(args)
        try:
            return await body(accel)
        finally:
            await accel.close()

    try:
        return asyncio.run(go())
    except DeviceFault as exc:
        print(f"soakcal sensor: {exc}", file=sys.stderr)
        return EXIT_FAILED


def _run_id(args: argparse.Namespace) -> int:
    from service.engine.identity import SensorMismatch, SerialBinding, check_identity

    async def body(accel: Any) -> int:
        ident = await accel.identify()
        problem = ""
        try:
            check_identity(ident, "-", SerialBinding("any"))
        except SensorMismatch as exc:
            problem = exc.message
        if args.json:
            print(json.dumps({**ident.as_dict(), "ok": not problem, "problem": problem or None}))
        else:
            d = ident.as_dict()
            ids = " ".join((d[k] or "--") for k in ("devid_ad", "devid_mst", "partid"))
            if ident.channel is not None:
                print(f"channel    {ident.channel}")
            print(f"model      {ident.model}\nfirmware   {ident.firmware}\n"
                  f"serial     {ident.serial or '(none: fixture EEPROM blank or absent)'}\n"
                  f"board uid  {ident.board_uid or '(not reported)'}\n"
                  f"part ids   {ids} (ADXL355: 0xAD 0x1D 0xED), revision {d['revid'] or '--'}")
            if problem:
                print(f"FAIL: {problem}")
        return EXIT_FAILED if problem else EXIT_OK

    return _run(args, body)


def _run_bind(args: argparse.Namespace) -> int:
    from drivers.faults import ValueOutOfRange

    async def body(accel: Any) -> int:
        try:
            stored = await accel.bind_serial(args.serial)
        except ValueOutOfRange as exc:
            print(f"soakcal sensor bind: {exc.message}", file=sys.stderr)
            return EXIT_BAD_INPUT
        ident = await accel.identify()
        print(f"bound {stored} to the fixture on bridge {ident.board_uid or '(no uid)'}")
        return EXIT_OK

    return _run(args, body)


def _run_read(args: argparse.Namespace) -> int:
    if args.samples < 1:
        print("soakcal sensor read: --samples must be ≥ 1", file=sys.stderr)
        return EXIT_BAD_INPUT

    async def body(accel: Any) -> int:
        acq = await accel.acquire(args.samples)
        mean = ", ".join(f"{v:+.6f}" for v in acq.mean_g)
        sd_ug = ", ".join(f"{v * 1e6:.1f}" for v in acq.sd_g)
        print(f"mean_g     ({mean}) g over {acq.n} samples\nsd_ug      ({sd_ug}) µg\n"
              f"sensor_c   {acq.sensor_c:.2f} °C (span {acq.sensor_c_span:.2f} °C)\n"
              f"saturated  {'yes' if acq.saturated else 'no'}")
        return EXIT_OK

    return _run(args, body)
