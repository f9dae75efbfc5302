"""``soakcal``: one command, argparse subcommands per docs/cli.md.

Subcommands owned by other packages are registered here (so ``--help`` lists
them and their arguments are validated) but imported only when run, so a
missing module is a clear one-line error for that subcommand, not a crash of
the whole CLI.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
ROLES = ("viewer", "operator", "admin")


def main(argv: Sequence[str] | None = None) -> int:
    try:
        code = _main(argv)
        sys.stdout.flush()  # a closed pipe shows here, not at exit as "Exception ignored"
    except BrokenPipeError:
        # `soakcal campaign list | head`: the reader has what it wanted. Nothing more can be
        # written; point stdout at /dev/null so the interpreter's final flush is silent too.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_OK
    return code


# A comma list starting with a minus sign (`--setpoints -40,20`): argparse takes it for an
# option and says only "expected one argument"; it is joined to its option as `=-40,20`.
# The value's own parser then says what is wrong with it (`-40,x`: "'x' is not a ...").
_NEGATIVE_LIST = re.compile(r"^-\.?\d[^=]*,")


def join_negative_lists(argv: list[str]) -> list[str]:
    """``["--setpoints", "-40,20"]`` → ``["--setpoints=-40,20"]`` (an option then a value
    argparse would refuse as another option); everything else unchanged."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        if (arg.startswith("--") and "=" not in arg and i + 1 < len(argv)
                and _NEGATIVE_LIST.match(argv[i + 1])):
            out.append(f"{arg}={argv[i + 1]}")
            i += 2
            continue
        out.append(arg)
        i += 1
    return out


def _main(argv: Sequence[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "sim":  # everything after `sim` belongs to the simulators' own parser
        return _delegate("simulators.cli", "run_sim", "sim")(argv[1:])
    argv = join_negative_lists(argv)
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    overwrite = _overwrites_an_input(args)
    if overwrite:
        _fail(f"soakcal {args.command}: {overwrite}")
        return EXIT_BAD_INPUT
    try:
        result = args.handler(args)
    except KeyboardInterrupt:
        return 130
    return EXIT_OK if result is None else int(result)


def _overwrites_an_input(args: argparse.Namespace) -> str | None:
    """Why ``-o`` (or ``--write-twin``) may not be written: it names one of the inputs."""
    from calibration.errors import RecordingError
    from calibration.recording import check_output_path

    inputs = [getattr(args, n, None) for n in ("recording", "model", "raw", "against")]
    for out in (getattr(args, "output", None), getattr(args, "write_twin", None)):
        if not isinstance(out, str):
            continue
        for src in inputs:
            if isinstance(src, str):
                try:
                    check_output_path(src, out)
                except RecordingError as exc:
                    return f"{exc} ({src})" if "overwrite" in str(exc) else str(exc)
    return None


class _OneLineParser(argparse.ArgumentParser):
    """argparse whose usage errors are one line on stderr and exit 2 (docs/cli.md)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(
        prog="soakcal",
        description="Thermal-soak calibration of triaxial MEMS accelerometers.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_calibration_commands(sub)
    _add_export(sub)
    _add_serve(sub)
    _add_engine_hosts(sub)
    _add_token(sub)
    _add_campaign(sub)
    _add_sensor(sub)
    _add_rig(sub)
    _add_ops(sub)
    _add_twin(sub)
    demo = sub.add_parser("demo", help="run one simulated campaign (soak or ramp) end to end")
    demo.add_argument("--out", metavar="DIR", help="where the recording, model and report go")
    demo.add_argument("--fast", action="store_true", help="a shorter campaign (smoke test)")
    demo.add_argument("--method", choices=("soak", "ramp"), default="soak",
                      help="soak (default) or ramp: the chamber ramps −40 → 60 °C and back "
                      "while the table sweeps (docs/ramp-campaigns.md)")
    demo.set_defaults(handler=_delegate("service.demo", "run_demo", "demo"))
    _add_demo_sensors(sub)
    sub.add_parser(
        "sim",
        help="simulated devices (arguments are passed to the simulators' CLI)",
        add_help=False,
    )
    return parser


# --- subcommands implemented elsewhere ------------------------------------------------


def _add_demo_sensors(sub: Any) -> None:
    """``soakcal demo --sensors N``: a fixture of N simulated sensors (service/demo.py)."""

    def sensors_count(text: str) -> int:  # service.demo is loaded only when the flag is used
        from service.demo import sensors_count as parse

        return parse(text)

    sub.choices["demo"].add_argument(
        "--sensors", type=sensors_count, default=1, metavar="N",
        help="sensors calibrated together in one campaign (1…64, default 1)")
    sub.choices["demo"].add_argument(
        "--position-order", choices=("travel", "table", "balanced"), default=None,
        help="order of each step's positions (default: the engine's, travel; docs/engine.md)")


def _add_calibration_commands(sub: Any) -> None:
    cal = sub.add_parser("calibrate", help="fit the thermal model to a recording")
    cal.add_argument("recording", metavar="RECORDING", help="recording v1 CSV")
    cal.add_argument("-o", "--output", required=True, metavar="MODEL", help="model JSON to write")
    cal.add_argument("--json", action="store_true", help="print the table as JSON")
    cal.add_argument("--report-dir", metavar="DIR", help="write the report (plots) here")
    cal.add_argument(
        "--method",
        choices=("joint", "per_step"),
        help="thermal fit: one joint fit over all steps (default) or per step then per "
        "parameter; docs/calibration.md compares them",
    )
    cal.add_argument("--gravity-g", type=float, metavar="G",
                     help="local gravity in units of standard gravity (9.80665 m/s^2); "
                     "the reference directions are scaled to it (default 1.0)")
    cal.add_argument("--latitude-deg", type=float, metavar="L",
                     help="local gravity from WGS84 normal gravity at this latitude (deg)")
    cal.add_argument("--height-m", type=float, metavar="H",
                     help="with --latitude-deg: ellipsoidal height (m), free-air corrected")
    cal.add_argument("--rate-gain-ug-per-c-per-min", metavar="X,Y,Z",
                     help="the sensor's measured temperature_rate gain per axis (µg per "
                     "°C/min, e.g. a campaign's provenance): k·dT/dt is subtracted from every "
                     "row before the fit")
    cal.set_defaults(handler=_delegate("calibration.cli", "run_calibrate", "calibrate"))

    comp = sub.add_parser("compensate", help="apply a model to a recording")
    comp.add_argument("model", metavar="MODEL", help="model JSON")
    comp.add_argument("recording", metavar="RECORDING", help="recording v1 CSV")
    comp.add_argument("-o", "--output", required=True, metavar="OUT", help="CSV to write")
    comp.add_argument(
        "--extrapolate", action="store_true", help="allow temperatures outside the valid range"
    )
    comp.add_argument(
        "--smooth-temperature-s",
        type=_positive_float,
        metavar="S",
        help="smooth the noisy temperature channel over S seconds before compensating",
    )
    comp.add_argument("--raw-temperature", action="store_true",
                      help="use each row's own temperature reading (default: condition it as "
                      "the model file says, per step or by the causal filter)")
    comp.set_defaults(handler=_delegate("calibration.cli", "run_compensate", "compensate"))

    diag = sub.add_parser("diagnose", help="what physics the base model left out")
    diag.add_argument("recording", metavar="RECORDING", help="recording v1 CSV")
    diag.add_argument("--model", metavar="MODEL", help="model JSON (default: fit one)")
    diag.add_argument("--json", action="store_true", help="print JSON")
    diag.add_argument("--report-dir", metavar="DIR", help="write the report here")
    diag.add_argument("--seed", type=int, metavar="N", help="random seed")
    diag.add_argument("--n-null", type=int, metavar="N", help="null-distribution draws")
    diag.add_argument("--against", metavar="FILE", help="model or twin JSON held fixed (no refit)")
    diag.add_argument("--write-twin", metavar="OUT", help="with --against: corrected twin JSON")
    diag.set_defaults(handler=_delegate("calibration.cli", "run_diagnose", "diagnose"))

    imp = sub.add_parser("import", help="convert a raw recording to recording format v1")
    imp.add_argument("--format", required=True, metavar="FMT",
                     help="openaxes, imu_tk, ferraris, mpu6050, ulog (PX4), dataflash "
                     "(ArduPilot) or csv")
    imp.add_argument("raw", metavar="RAW", help="raw input file")
    imp.add_argument("-o", "--output", required=True, metavar="REC", help="recording to write")
    imp.add_argument("--min-static-s", type=float, metavar="S", help="shortest static segment")
    imp.add_argument("--threshold", type=float, metavar="X", help="static-detection threshold")
    imp.add_argument(
        "--raw",
        dest="raw_samples",
        action="store_true",
        help="write every raw sample as a row instead of one averaged row per static interval",
    )
    imp.add_argument("--sensor", choices=("adxl355", "bmi160"), help="openaxes: which sensor")
    imp.add_argument("--counts-per-g", metavar="K|KX,KY,KZ", help="imu_tk/csv: counts per g")
    imp.add_argument("--offset", metavar="O|OX,OY,OZ", help="imu_tk/csv: offset in counts")
    imp.add_argument("--session-list", metavar="JSON", help="ferraris: the session list")
    imp.add_argument("--window-s", type=float, metavar="S", help="static-detection window")
    imp.add_argument("--trim-s", type=float, metavar="S", help="trimmed from each interval end")
    imp.add_argument("--block-s", type=float, metavar="S",
                     help="one row per consecutive S-second block (mean, sd, n, temperature)")
    imp.add_argument("--instance", type=int, metavar="N",
                     help="ulog/dataflash: which accelerometer (0 = the first)")
    imp.add_argument("--columns", metavar="ROLE=COL,...",
                     help="csv: t=,ax=,ay=,az=,temp= source column names")
    imp.add_argument("--delimiter", metavar="D", help="csv: ',' ';' or 'tab' (default: sniffed)")
    imp.add_argument("--accel-unit", choices=("g", "mg", "m/s2", "counts"),
                     help="csv: acceleration unit (required; counts needs --counts-per-g)")
    imp.add_argument("--temp-unit", choices=("C", "F", "K", "counts"),
                     help="csv: temperature unit (default C)")
    imp.add_argument("--temp-c-per-count", type=float, metavar="K",
                     help="csv/openaxes: degC per temperature count")
    imp.add_argument("--temp-offset-c", type=float, metavar="C",
                     help="csv/openaxes: degC at temperature count 0")
    imp.add_argument("--time-unit", choices=("s", "ms", "us"), help="csv: time unit (default s)")
    imp.add_argument("--rate-hz", type=float, metavar="HZ",
                     help="csv without a time column: t = i / HZ")
    imp.add_argument("--bad-lines", choices=("refuse", "skip"),
                     help="csv: a line that is not a row of the table (a garbled serial-log "
                     "line) is refused (default), or skipped and named (at most 1 %% of lines)")
    imp.set_defaults(handler=_delegate("calibration.importers_cli", "run_import", "import"))


def _add_export(sub: Any) -> None:
    exp = sub.add_parser("export", help="export a model for firmware (C99 header) or other code")
    exp.add_argument("model", metavar="MODEL", help="model JSON from calibrate")
    exp.add_argument("--format", choices=("c", "json-flat", "px4", "ardupilot"), default="c",
                     help="c: one C99 header (default); json-flat: plain arrays and a recipe; "
                     "px4: TC_A* parameter file; ardupilot: INS_TCAL* parameter file")
    exp.add_argument("--instance", type=int, metavar="N",
                     help="px4: TC_A<N> (0-3, default 0); ardupilot: INS_TCAL<N> (1-3, default 1)")
    exp.add_argument("--device-id", type=int, metavar="ID",
                     help="px4: TC_A<N>_ID, the accelerometer's device id (CAL_ACCn_ID)")
    exp.add_argument("--rate-term", choices=("fold", "drop"), default="fold",
                     help="px4/ardupilot, a warm-up model with a rate term: fold its average "
                     "over the fit log into the polynomial (default: right for warm-ups like "
                     "it) or drop it (right at constant temperature)")
    exp.add_argument("--temperature-reading", choices=("filtered", "per-sample"),
                     help="ardupilot, a dithered coarse temperature channel: the reading the "
                     "board's IMU driver hands INS_TCAL: filtered (InvenSense MPU-6000/9250, "
                     "ICM-2060x/20689: 1-Hz low-pass; the default) or per-sample (ICM-42xxx, "
                     "BMI088); px4: per-sample only")
    exp.add_argument("-o", "--output", required=True, metavar="OUT", help="file to write")
    exp.set_defaults(handler=_delegate("calibration.export_cli", "run_export", "export"))


def _add_twin(sub: Any) -> None:
    twin = sub.add_parser("twin", help="digital twins fitted to real recordings")
    tsub = twin.add_subparsers(dest="twin_command", metavar="ACTION", required=True)
    fit = tsub.add_parser("fit", help="fit a twin (sensor model with its effects, die lag, "
                          "noise) to a recording")
    fit.add_argument("recording", metavar="RECORDING", help="recording v1 CSV")
    fit.add_argument("-o", "--output", required=True, metavar="TWIN", help="twin JSON to write")
    fit.add_argument("--json", action="store_true", help="print the report as JSON")
    fit.add_argument("--no-effects", action="store_true",
                     help="do not diagnose the recording: the twin carries no catalogue effect")
    fit.set_defaults(handler=_delegate("calibration.discrepancy.twin_cli", "run_twin_fit",
                                       "twin fit"))


def _delegate(module: str, function: str, command: str) -> Callable[[Any], int]:
    """A handler importing ``module.function`` when the subcommand runs."""

    def handler(args: Any) -> int:
        try:
            target = getattr(importlib.import_module(module), function)
        except ImportError as exc:
            missing = getattr(exc, "name", None)
            if missing and (module == missing or module.startswith(missing + ".")):
                _fail(f"soakcal {command}: not available in this installation ({module} missing)")
                return EXIT_FAILED
            raise
        except AttributeError:
            _fail(f"soakcal {command}: {module} has no {function}()")
            return EXIT_FAILED
        result = target(args)
        return EXIT_OK if result is None else int(result)

    return handler


# --- serve and token -------------------------------------------------------------------


def _add_serve(sub: Any) -> None:
    serve = sub.add_parser("serve", help="run the REST service (migrates the database first)")
    serve.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    serve.add_argument(
        "--sim-speed",
        type=_positive_float,
        default=600.0,
        metavar="FACTOR",
        help="simulated time runs FACTOR times faster than the wall clock (default 600)",
    )
    serve.set_defaults(handler=_run_serve)


def _run_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.api.app import create_app
    from service.config import ConfigError, Settings
    from service.db.session import DatabaseUnavailable, upgrade_database

    url = _database_or_fail("serve")
    if url is None:
        return EXIT_BAD_INPUT
    try:
        settings = Settings(database_url=url, sim_speed=args.sim_speed, migrate=False)
        upgrade_database(settings.database_url)
    except (ConfigError, DatabaseUnavailable) as exc:
        _fail(f"soakcal serve: {exc}")
        return EXIT_BAD_INPUT
    uvicorn.run(create_app(settings), host=args.host, port=args.port)
    return EXIT_OK


def _add_token(sub: Any) -> None:
    token = sub.add_parser("token", help="API tokens")
    token_sub = token.add_subparsers(dest="token_command", metavar="ACTION", required=True)
    create = token_sub.add_parser("create", help="create a token; it is printed as the last line")
    create.add_argument("--role", required=True, choices=ROLES)
    create.add_argument("--name", help="who or what the token is for")
    create.set_defaults(handler=_run_token_create)
    _add_token_actions(token_sub, create)


def _run_token_create(args: argparse.Namespace) -> int:
    from service.api.auth import create_token
    from service.db.session import (
        DatabaseUnavailable,
        make_session_factory,
        session_scope,
        upgrade_database,
    )

    url = _database_or_fail("token create")
    if url is None:
        return EXIT_BAD_INPUT
    try:
        upgrade_database(url)  # so a token can be made before the first `serve`
    except DatabaseUnavailable as exc:
        _fail(f"soakcal token create: {exc}")
        return EXIT_BAD_INPUT
    factory = make_session_factory(url)
    try:
        with session_scope(factory) as session:
            token = create_token(session, args.role, args.name, args.expires_days)
    finally:
        factory.kw["bind"].dispose()
    label = f" '{args.name}'" if args.name else ""
    print(f"created {args.role} token{label} in {_redacted(url)}; it is shown only once:")
    print(token)
    return EXIT_OK


def _database_or_fail(command: str) -> str | None:
    """The database every subcommand uses (service.config), announced on stderr; None if bad."""
    from service.config import ConfigError, check_database_url, database_choice

    url, why = database_choice()
    try:
        check_database_url(url)
    except ConfigError as exc:
        _fail(f"soakcal {command}: {exc}")
        return None
    print(f"soakcal {command}: database {_redacted(url)} ({why})", file=sys.stderr)
    return url


def _redacted(url: str) -> str:
    from sqlalchemy import make_url

    return make_url(url).render_as_string(hide_password=True)


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


# --- rigs on several hosts: serve --rigs, worker (service/engine/worker.py) ---------------


def _add_engine_hosts(sub: Any) -> None:
    """``serve --rigs NAME,…|none`` and ``worker --rigs NAME,…`` (after ``_add_serve``)."""
    from service.engine.worker import rigs_argument

    rigs_help = ("drive only these rigs' campaigns ('none': API only; default: every rig)")
    serve = sub.choices["serve"]
    serve.add_argument("--rigs", type=rigs_argument, default=None, metavar="NAME,…|none",
                       help=rigs_help)
    run_serve = serve.get_default("handler")

    def serve_with_rigs(args: argparse.Namespace) -> int:
        if args.rigs is not None:  # Settings reads it (service/config.py engine_rigs)
            import os

            from service.config import ENGINE_RIGS_ENV

            os.environ[ENGINE_RIGS_ENV] = args.rigs
        return int(run_serve(args))

    serve.set_defaults(handler=serve_with_rigs)
    worker = sub.add_parser("worker", help="run the campaign engine for some rigs, no HTTP")
    worker.add_argument("--rigs", type=rigs_argument, required=True, metavar="NAME,…",
                        help="the rigs this process drives (their devices are on this host)")
    worker.add_argument("--sim-speed", type=_positive_float, default=600.0, metavar="FACTOR",
                        help="simulated rigs run FACTOR times faster than the wall clock")
    worker.set_defaults(handler=_delegate("service.engine.worker", "run_worker", "worker"))


# --- campaign (REST client) ------------------------------------------------------------


def _add_campaign(sub: Any) -> None:
    from service import cli_campaign

    cli_campaign.add_parser(sub)


def _add_sensor(sub: Any) -> None:
    from service import cli_sensor

    cli_sensor.add_parser(sub)


def _add_rig(sub: Any) -> None:
    """``soakcal rig check NAME [--move]`` (service/rig_check.py)."""
    from service import rig_check

    rig_check.add_parser(sub)


def _add_token_actions(token_sub: Any, create: Any) -> None:
    from service import cli_ops

    cli_ops.add_token_actions(token_sub, create)  # --expires-days, token list, token revoke


def _add_ops(sub: Any) -> None:
    from service import cli_ops

    cli_ops.add_schedule(sub)
    cli_ops.add_coefficients(sub)


def _fail(message: str) -> None:
    print(message, file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
