"""``soakcal campaign plan``: the API's dry run (service.dry_run) on the command line.

Needs no running service: the rig is read from the same database ``soakcal
serve`` uses (service.config); the built-in ``sim`` rig is known even before
the database exists. Exit 0 with the plan summary, 2 with the field and why.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

EXIT_OK, EXIT_BAD_INPUT = 0, 2
PROG = "soakcal campaign plan"


def add_plan_parser(actions: Any) -> None:
    """Register ``plan`` under ``soakcal campaign``."""
    plan = actions.add_parser(
        "plan", help="dry-run a campaign on a rig: refuse what cannot calibrate, predict time")
    plan.add_argument("--rig", default="sim", help="rig name (default sim)")
    plan.add_argument("--spec", metavar="FILE.json",
                      help="a campaign spec (the POST /campaigns body; rig/sensor optional)")
    plan.add_argument("--positions", help="position schedule (default table1)")
    plan.add_argument("--setpoints", metavar="C,C,...",
                      help="setpoints in °C, e.g. --setpoints=-40,-20,0 (default -40..60)")
    plan.add_argument("--soak-min", type=float, help="soak per step in minutes (default 60)")
    plan.add_argument("--samples-per-position", type=int, help="default 200")
    plan.add_argument("--ramp-c-per-min", type=float,
                      help="chamber ramp, °C/min (default 1; 2 with --method ramp)")
    plan.add_argument("--stability", help="predictive | dwell | fixed (default predictive)")
    plan.add_argument("--method", choices=("soak", "ramp"),
                      help="soak (default) or ramp (legs through the range and back while "
                      "the table sweeps: docs/ramp-campaigns.md)")
    plan.add_argument("--json", action="store_true", help="print the verdict as JSON")
    plan.set_defaults(handler=run_plan)


def run_plan(args: argparse.Namespace) -> int:
    try:
        body = _spec_body(args)
    except ValueError as exc:
        return _refuse(str(exc))
    from pydantic import ValidationError

    from service.engine.spec import EngineSpec

    try:
        spec = EngineSpec.model_validate(body)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "spec"
        return _refuse(f"{where}: {first['msg']}")
    try:
        rig = _rig(args.rig)
    except RuntimeError as exc:
        return _refuse(str(exc))
    from service.dry_run import check_campaign

    check = check_campaign(spec, rig, args.rig)
    if args.json:
        print(json.dumps({
            "ok": check.ok, "rig": args.rig, "predicted_duration_s": check.predicted_duration_s,
            "steps": check.n_steps, "positions": check.n_positions, "mode": check.mode,
            "issues": [{"loc": list(i.loc), "msg": i.msg} for i in check.issues]}))
    if not check.ok:
        for issue in check.issues:
            where = ".".join(str(p) for p in issue.loc)
            print(f"{PROG}: {where}: {issue.msg}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if not args.json:
        print(f"plan on rig {args.rig!r}: {check.summary()}")
    return EXIT_OK


def read_spec_file(path_text: str) -> dict[str, Any]:
    """A campaign spec file (the ``POST /campaigns`` body as JSON); ``ValueError`` naming the
    file, and the line and column when it is not JSON."""
    path = Path(path_text)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read ({exc.__class__.__name__}: "
                         f"{getattr(exc, 'strerror', None) or exc})") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}:{exc.lineno}:{exc.colno}: not JSON ({exc.msg})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: expected a JSON object (the campaign spec)")
    return doc


def _spec_body(args: argparse.Namespace) -> dict[str, Any]:
    from service.cli_campaign import parse_setpoints

    body: dict[str, Any] = {}
    if args.spec:
        body.update({k: v for k, v in read_spec_file(args.spec).items()
                     if k not in ("rig", "sensor", "sensors")})
    if args.setpoints is not None:
        try:
            body["setpoints_c"] = parse_setpoints(args.setpoints)
        except argparse.ArgumentTypeError as exc:
            raise ValueError(f"--setpoints: {exc}") from None
    for key in ("positions", "soak_min", "samples_per_position", "ramp_c_per_min",
                "stability", "method"):
        value = getattr(args, key)
        if value is not None:
            body[key] = value
    return body


def _rig(name: str) -> dict[str, Any] | None:
    """The rig's config from the service's database; the built-in sim rig if none is stored."""
    from service.campaigns import SIM_RIG, SIM_RIG_NAME
    from service.config import ConfigError, check_database_url, database_choice

    url, why = database_choice()
    try:
        check_database_url(url)
    except ConfigError as exc:
        raise RuntimeError(str(exc)) from None
    print(f"{PROG}: database {_redacted(url)} ({why})", file=sys.stderr)
    stored = _stored_rig(url, name)
    if stored is None and name == SIM_RIG_NAME:
        return dict(SIM_RIG)
    return stored


def _stored_rig(url: str, name: str) -> dict[str, Any] | None:
    from sqlalchemy import create_engine, inspect, make_url, select
    from sqlalchemy.exc import SQLAlchemyError

    from service.db.models import Rig

    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite" and parsed.database and not Path(
            parsed.database).exists():
        return None  # no database yet: do not create one just to look
    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            if not inspect(conn).has_table("rigs"):
                return None
            row = conn.execute(select(Rig.name, Rig.chamber, Rig.turntable, Rig.sensors)
                               .where(Rig.name == name)).first()
    except SQLAlchemyError as exc:
        reason = (str(getattr(exc, "orig", None) or exc).strip().splitlines() or ["?"])[0]
        raise RuntimeError(f"cannot open the database {_redacted(url)}: {reason[:200]}") from None
    finally:
        engine.dispose()
    if row is None:
        return None
    return {"name": row.name, "chamber": row.chamber, "turntable": row.turntable,
            "sensors": row.sensors}


def _redacted(url: str) -> str:
    from sqlalchemy import make_url

    return make_url(url).render_as_string(hide_password=True)


def _refuse(message: str) -> int:
    print(f"{PROG}: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT
