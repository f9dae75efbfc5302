"""Operations from the command line: ``soakcal token list|revoke``, ``soakcal schedule
add|list|rm`` and ``soakcal coefficients SERIAL --temperature-c T``.

Tokens are managed in the database directly, like ``soakcal token create``
(an admin on the service's host, before any token exists); schedules and
coefficients go through the REST service like ``soakcal campaign``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
from typing import Any
from urllib.parse import quote

from service.cli_campaign import (
    add_campaign_options,
    call,
    campaign_body,
    client_options,
    guarded,
    print_listing,
)

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
MAX_EXPIRES_DAYS = 3650


# --- token ------------------------------------------------------------------------------


def add_token_actions(token_sub: Any, create: argparse.ArgumentParser) -> None:
    """``--expires-days`` on ``token create``; ``token list`` and ``token revoke ID``."""
    create.add_argument(
        "--expires-days",
        type=_expires_days,
        metavar="DAYS",
        help="the token is refused after DAYS days (default: never expires)",
    )
    listing = token_sub.add_parser("list", help="list tokens (never their secrets)")
    listing.add_argument("--json", action="store_true", help="print JSON")
    listing.set_defaults(handler=run_token_list)
    revoke = token_sub.add_parser("revoke", help="revoke a token: its next request gets 401")
    revoke.add_argument("id", type=_token_id, metavar="ID", help="token id (see token list)")
    revoke.set_defaults(handler=run_token_revoke)


def _expires_days(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of days, got {text!r}") from None
    if not 0 < value <= MAX_EXPIRES_DAYS:
        raise argparse.ArgumentTypeError(f"must be in (0, {MAX_EXPIRES_DAYS}] days, got {text}")
    return value


def _token_id(text: str) -> int:
    if not text.isascii() or not text.isdigit() or not 1 <= int(text) < 2**31:
        raise argparse.ArgumentTypeError(f"expected a token id (a positive integer), got {text!r}")
    return int(text)


def _session_factory(command: str = "token") -> tuple[Any, str]:
    """The database every subcommand uses, migrated; a bad URL or an unreachable database
    is one line on stderr and exit 2 (the same rules as ``token create``)."""
    from service.cli import EXIT_BAD_INPUT, _database_or_fail
    from service.db.session import DatabaseUnavailable, make_session_factory, upgrade_database

    url = _database_or_fail(command)
    if url is None:
        raise SystemExit(EXIT_BAD_INPUT)
    try:
        upgrade_database(url)  # so these work before the first `serve`, like `token create`
    except DatabaseUnavailable as exc:
        print(f"soakcal {command}: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from None
    return make_session_factory(url), url


def _redacted(url: str) -> str:
    from sqlalchemy import make_url

    return make_url(url).render_as_string(hide_password=True)


def run_token_list(args: argparse.Namespace) -> int:
    from sqlalchemy import select

    from service.api.tokens import token_out
    from service.db.models import ApiToken

    factory, url = _session_factory("token list")
    try:
        with factory() as session:
            rows = [token_out(r) for r in session.scalars(select(ApiToken).order_by(ApiToken.id))]
    finally:
        factory.kw["bind"].dispose()
    if args.json:
        print(json.dumps([r.model_dump(mode="json") for r in rows], indent=2))
        return EXIT_OK
    print(f"tokens in {_redacted(url)}:", file=sys.stderr)
    print(
        f"{'id':>4}  {'role':<8} {'status':<8} {'last used (UTC)':<16}  "
        f"{'expires (UTC)':<16}  name"
    )
    for r in rows:
        print(
            f"{r.id:>4}  {r.role:<8} {r.status:<8} {_utc(r.last_used_at):<16}  "
            f"{_utc(r.expires_at):<16}  {r.name or ''}"
        )
    return EXIT_OK


def run_token_revoke(args: argparse.Namespace) -> int:
    from service.db.models import ApiToken
    from service.db.timestamps import utcnow
    from service.event_log import log_event

    factory, url = _session_factory("token revoke")
    try:
        with factory() as session:
            row = session.get(ApiToken, args.id)
            if row is None:
                print(f"soakcal token revoke: no token {args.id} in {_redacted(url)}",
                      file=sys.stderr)
                return EXIT_BAD_INPUT
            if row.revoked_at is None:
                row.revoked_at = utcnow()
                session.commit()
                log_event("token revoked", token_id=args.id, role=row.role, name=row.name)
            print(f"token {args.id} ({row.role}{', ' + row.name if row.name else ''}) revoked")
    finally:
        factory.kw["bind"].dispose()
    return EXIT_OK


def _utc(value: dt.datetime | None) -> str:
    return "-" if value is None else f"{value.astimezone(dt.UTC):%Y-%m-%d %H:%M}"


# --- schedule ----------------------------------------------------------------------------


def add_schedule(sub: Any) -> None:
    schedule = sub.add_parser("schedule", help="overnight campaigns at a time or on a cron")
    actions = schedule.add_subparsers(dest="schedule_command", metavar="ACTION", required=True)
    common = client_options()

    add = actions.add_parser("add", parents=[common], help="schedule a campaign")
    when = add.add_mutually_exclusive_group(required=True)
    when.add_argument("--at", metavar="ISO", help="once, at this ISO-8601 time (naive: UTC)")
    when.add_argument("--cron", metavar="EXPR", help="repeatedly, e.g. '0 20 * * 1-5'")
    add.add_argument("--timezone", metavar="IANA", help="the cron's wall clock (default UTC)")
    add_campaign_options(add)
    add.set_defaults(handler=_schedule_add)

    listing = actions.add_parser("list", parents=[common], help="list schedules")
    listing.add_argument("--json", action="store_true", help="print JSON")
    listing.set_defaults(handler=_schedule_list)

    rm = actions.add_parser("rm", parents=[common], help="remove a schedule")
    rm.add_argument("id", type=_token_id, metavar="ID")
    rm.set_defaults(handler=_schedule_rm)


@guarded("schedule")
def _schedule_add(args: argparse.Namespace) -> int:
    body: dict[str, Any] = {"campaign": campaign_body(args)}
    # exactly one of at/cron: the API refuses an explicit null for the other
    body.update({k: v for k, v in (("at", args.at), ("cron", args.cron)) if v is not None})
    if args.timezone:
        body["timezone"] = args.timezone
    s = call(args, "POST", "/api/v1/schedules", json=body)
    print(f"schedule {s['id']}: {_trigger(s)}, next run {_utc_text(s.get('next_run_at'))}")
    return EXIT_OK


@guarded("schedule")
def _schedule_list(args: argparse.Namespace) -> int:
    def row(s: dict[str, Any]) -> str:
        c = s["campaign"]
        return (f"{s['id']:>4}  {_utc_text(s.get('next_run_at')):<16}  {c['rig']:<8} "
                f"{c['sensor']:<12} {_trigger(s)}")

    return print_listing(
        args, "/api/v1/schedules",
        f"{'id':>4}  {'next run (UTC)':<16}  {'rig':<8} {'sensor':<12} trigger", row)


@guarded("schedule")
def _schedule_rm(args: argparse.Namespace) -> int:
    call(args, "DELETE", f"/api/v1/schedules/{args.id}")
    print(f"schedule {args.id} removed")
    return EXIT_OK


def _trigger(s: dict[str, Any]) -> str:
    if s.get("cron"):
        return f"cron '{s['cron']}' ({s.get('timezone') or 'UTC'})"
    return f"once at {_utc_text(s.get('at'))} UTC"


def _utc_text(iso: str | None) -> str:
    if not iso:
        return "-"
    value = dt.datetime.fromisoformat(iso)
    if value.tzinfo is None:
        value = value.replace(tzinfo=dt.UTC)
    return f"{value.astimezone(dt.UTC):%Y-%m-%d %H:%M}"


# --- coefficients ------------------------------------------------------------------------


def add_coefficients(sub: Any) -> None:
    coef = sub.add_parser(
        "coefficients",
        parents=[client_options()],
        help="a sensor's calibration matrix and bias at a temperature (REST client)",
    )
    coef.add_argument("serial", metavar="SERIAL", help="sensor serial")
    coef.add_argument("--temperature-c", type=_finite, required=True, metavar="T", help="°C")
    coef.add_argument(
        "--extrapolate", action="store_true", help="allow T outside the valid range"
    )
    coef.add_argument("--json", action="store_true", help="print JSON")
    coef.set_defaults(handler=_coefficients)


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a temperature in °C, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite temperature, got {text!r}")
    return value


@guarded("coefficients")
def _coefficients(args: argparse.Namespace) -> int:
    params: dict[str, Any] = {"temperature_c": args.temperature_c}
    if args.extrapolate:
        params["extrapolate"] = "true"
    k = call(args, "GET", f"/api/v1/sensors/{quote(args.serial, safe='')}/coefficients",
             params=params)
    if args.json:
        print(json.dumps(k, indent=2))
        return EXIT_OK
    note = " (extrapolated)" if k["extrapolated"] else ""
    print(
        f"sensor {args.serial}, calibration {k['calibration_id']} at "
        f"{k['temperature_c']:.2f} °C{note}: calibrated = M · (raw − bias)"
    )
    print(f"{'':>3} {'M x':>12} {'M y':>12} {'M z':>12}  {'bias (mg)':>11}")
    for axis, row, bias_g in zip("xyz", k["matrix"], k["bias_g"], strict=True):
        cells = " ".join(f"{v:>12.8f}" for v in row)
        print(f"{axis:>3} {cells}  {bias_g * 1e3:>11.5f}")
    return EXIT_OK


# --- rig add | list | rm -----------------------------------------------------------------


def add_rig_admin_parsers(rig_sub: Any) -> None:
    """``soakcal rig add NAME --config RIG.json``, ``rig list``, ``rig rm NAME``: the rigs of
    ``/api/v1/rigs`` in the configured database, by the API's own rules (its handlers)."""
    add = rig_sub.add_parser("add", help="add a rig from a JSON config (POST /api/v1/rigs)")
    add.add_argument("name", metavar="NAME", help="rig name (letters, digits, _ . -)")
    add.add_argument("--config", required=True, metavar="RIG.json",
                     help='{"chamber": {...}, "turntable": {...}, "sensors": [...]}')
    add.set_defaults(handler=run_rig_add)
    listing = rig_sub.add_parser("list", help="list the rigs (the sim rig included)")
    listing.add_argument("--json", action="store_true", help="print JSON")
    listing.set_defaults(handler=run_rig_list)
    rm = rig_sub.add_parser("rm", help="remove a rig no campaign uses or names")
    rm.add_argument("name", metavar="NAME")
    rm.set_defaults(handler=run_rig_rm)


def _rig_session(command: str) -> tuple[Any, Any]:
    """A session on the configured database, with the ``sim`` rig present (a fresh install
    has it without ``serve`` having run)."""
    from service.campaigns import seed_sim_rig

    factory, _url = _session_factory(command)
    session = factory()
    seed_sim_rig(session)
    session.commit()
    return factory, session


def _http_refusal(command: str, where: str, exc: Any) -> int:
    """The API's refusal (404/409/422) as one line on stderr, exit 2."""
    detail = exc.detail
    if isinstance(detail, list):  # 422: [{"loc": ["body", "chamber", "x"], "msg": ...}]
        detail = "; ".join(
            f"{'.'.join(str(p) for p in d['loc'][1:])}: {d['msg']}" for d in detail)
    print(f"soakcal {command}: {where}{detail}", file=sys.stderr)
    return EXIT_BAD_INPUT


def run_rig_add(args: argparse.Namespace) -> int:
    from fastapi import HTTPException
    from pydantic import ValidationError

    from service.api.rigs import create_rig
    from service.api.schemas import RigCreate

    try:
        with open(args.config, encoding="utf-8") as fh:
            config = json.load(fh)
    except OSError as exc:
        print(f"soakcal rig add: {args.config}: cannot read ({exc.strerror})", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        print(f"soakcal rig add: {args.config}: not JSON ({exc})", file=sys.stderr)
        return EXIT_BAD_INPUT
    if not isinstance(config, dict):
        print(f"soakcal rig add: {args.config}: expected an object "
              '{"chamber", "turntable", "sensors"}', file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        body = RigCreate(**{**config, "name": args.name})
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        print(f"soakcal rig add: {args.config}: {where}: {first['msg']}", file=sys.stderr)
        return EXIT_BAD_INPUT
    factory, session = _rig_session("rig add")
    try:
        out = create_rig(body, session)
    except HTTPException as exc:
        return _http_refusal("rig add", f"{args.config}: " if exc.status_code == 422 else "",
                             exc)
    finally:
        session.close()
        factory.kw["bind"].dispose()
    print(f"rig {out.name} added: chamber {_rig_summary(out.chamber)}")
    return EXIT_OK


def run_rig_list(args: argparse.Namespace) -> int:
    from service.api.rigs import list_rigs

    factory, session = _rig_session("rig list")
    try:
        rigs = list_rigs(session)
    finally:
        session.close()
        factory.kw["bind"].dispose()
    if args.json:
        print(json.dumps([r.model_dump(mode="json") for r in rigs], indent=2))
        return EXIT_OK
    print(f"{'name':<16} {'busy':<5} chamber")
    for r in rigs:
        print(f"{r.name:<16} {'yes' if r.busy else 'no':<5} {_rig_summary(r.chamber)}")
    return EXIT_OK


def run_rig_rm(args: argparse.Namespace) -> int:
    from fastapi import HTTPException

    from service.api.rigs import delete_rig

    factory, session = _rig_session("rig rm")
    try:
        delete_rig(args.name, session)
    except HTTPException as exc:
        return _http_refusal("rig rm", "", exc)
    finally:
        session.close()
        factory.kw["bind"].dispose()
    print(f"rig {args.name} removed")
    return EXIT_OK


def _rig_summary(chamber: dict[str, Any]) -> str:
    driver = chamber.get("driver", "sim")
    if driver == "modbus":
        return f"modbus {chamber.get('url', '?')} map {chamber.get('map', 'eurotherm3216')}"
    return str(driver)
