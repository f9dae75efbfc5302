"""``soakcal campaign ...``: a thin REST client (httpx) of the running service."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from typing import Any

DEFAULT_URL = "http://127.0.0.1:8000"
EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
TERMINAL = ("completed", "failed", "aborted")


def client_options() -> argparse.ArgumentParser:
    """``--url`` and ``--token``, shared by every REST-client subcommand."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--url",
        default=os.environ.get("SOAKCAL_URL", DEFAULT_URL),
        help=f"service URL (default {DEFAULT_URL})",
    )
    common.add_argument("--token", default=None, help="API token (default: $SOAKCAL_TOKEN)")
    return common


def add_parser(sub: Any) -> None:
    campaign = sub.add_parser("campaign", help="start, watch and control campaigns (REST client)")
    common = client_options()
    actions = campaign.add_subparsers(dest="campaign_command", metavar="ACTION", required=True)

    start = actions.add_parser("start", parents=[common], help="queue a campaign")
    add_campaign_options(start, spec_file=True)
    start.add_argument("--watch", action="store_true", help="follow it until it ends")
    start.set_defaults(handler=_start)

    watch = actions.add_parser("watch", parents=[common], help="live progress until it ends")
    watch.add_argument("id", type=int)
    watch.set_defaults(handler=_watch)

    for action in ("pause", "resume", "abort"):
        p = actions.add_parser(action, parents=[common], help=f"{action} a campaign")
        p.add_argument("id", type=int)
        p.set_defaults(handler=_control, action=action)

    listing = actions.add_parser("list", parents=[common], help="list campaigns")
    listing.add_argument("--state", choices=("queued", "running", "paused", *TERMINAL))
    listing.add_argument("--json", action="store_true", help="print JSON")
    listing.set_defaults(handler=_list)

    from service.cli_plan import add_plan_parser  # the dry run needs no running service

    add_plan_parser(actions)
    from service.cli_placement import add_placement_parser  # hand-placed fixtures

    add_placement_parser(actions)


def add_campaign_options(parser: argparse.ArgumentParser, *, spec_file: bool = False) -> None:
    """The campaign a request asks for (``campaign start``, ``schedule add``);
    :func:`campaign_body` turns them into the API's campaign object. With ``spec_file``
    a ``--spec FILE`` gives the whole body, and the options given override its keys."""
    if spec_file:
        parser.add_argument(
            "--spec", metavar="FILE.json",
            help="the campaign as JSON (the POST /campaigns body, any key of docs/api.md); "
            "options given here override its keys")
    parser.add_argument("--rig", default=None if spec_file else "sim",
                        help="rig name (default sim)")
    parser.add_argument("--sensor", required=not spec_file,
                        help="sensor serial, e.g. SN-0001")
    parser.add_argument(
        "--setpoints",
        type=parse_setpoints,
        metavar="C,C,...",
        help="setpoints in °C, e.g. --setpoints -40,-20,0 (default -40..60 step 10)",
    )
    parser.add_argument("--soak-min", type=float, help="soak per step in minutes (default 60)")
    parser.add_argument("--positions", help="position schedule (default table1)")
    parser.add_argument("--samples-per-position", type=int, help="default 200")


def campaign_body(args: argparse.Namespace) -> dict[str, Any]:
    """The API's campaign object from :func:`add_campaign_options`' arguments; an option
    not given is left out so the service applies its default."""
    body: dict[str, Any] = {}
    if getattr(args, "spec", None):
        from service.cli_plan import read_spec_file

        body.update(read_spec_file(args.spec))
    if args.rig is not None or "rig" not in body:
        body["rig"] = args.rig or "sim"
    if args.sensor is not None:
        body.pop("sensors", None)
        body["sensor"] = args.sensor
    if "sensor" not in body and "sensors" not in body:
        raise ValueError(f"{args.spec}: names no sensor; add \"sensor\" to the file or give "
                         "--sensor SERIAL" if getattr(args, "spec", None)
                         else "name the sensor: --sensor SERIAL")
    optional = {
        "setpoints_c": args.setpoints,
        "soak_min": args.soak_min,
        "positions": args.positions,
        "samples_per_position": args.samples_per_position,
    }
    body.update({k: v for k, v in optional.items() if v is not None})
    return body


def parse_setpoints(text: str) -> list[float]:
    """``-40,-20,0`` → ``[-40.0, -20.0, 0.0]``; what is wrong, in the person's words."""
    values: list[float] = []
    for part in text.split(","):
        if not part.strip():
            continue
        try:
            values.append(float(part))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{part.strip()[:20]!r} is not a temperature; expected °C numbers separated "
                "by commas, e.g. -40,-20,0") from None
    if not values:
        raise argparse.ArgumentTypeError("no setpoints given; expected e.g. -40,-20,0")
    return values


class ApiError(Exception):
    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def _client(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    import httpx

    token = args.token or os.environ.get("SOAKCAL_TOKEN")
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return httpx.Client(base_url=args.url.rstrip("/"), headers=headers, timeout=30.0)


def call(args: argparse.Namespace, method: str, path: str, **kwargs: Any) -> Any:
    import httpx

    try:
        with _client(args) as client:
            response = client.request(method, path, **kwargs)
    except httpx.HTTPError as exc:
        raise ApiError(0, f"cannot reach {args.url}: {exc}") from exc
    if response.status_code >= 400:
        raise ApiError(response.status_code, f"HTTP {response.status_code}: {_detail(response)}")
    return response.json() if response.content else None


def _detail(response: Any) -> str:
    try:
        detail = response.json().get("detail")
    except ValueError:
        return response.text.strip()[:200]
    if isinstance(detail, list):  # FastAPI validation errors: "loc: msg" for each
        return "; ".join(
            f"{'.'.join(str(p) for p in e.get('loc', []))}: {e.get('msg')}" for e in detail
        )
    return str(detail)


def guarded(command: str):  # type: ignore[no-untyped-def]
    """Decorator: an ``ApiError`` becomes one line ``soakcal COMMAND: ...`` and exit 2 / 1."""

    def wrap(handler):  # type: ignore[no-untyped-def]
        def run(args: argparse.Namespace) -> int:
            try:
                return handler(args)
            except ApiError as exc:
                print(f"soakcal {command}: {exc}", file=sys.stderr)
                return EXIT_BAD_INPUT if 400 <= exc.status < 500 else EXIT_FAILED

        return run

    return wrap


_guarded = guarded("campaign")


@_guarded
def _start(args: argparse.Namespace) -> int:
    try:
        body = campaign_body(args)
    except ValueError as exc:
        print(f"soakcal campaign start: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    campaign = call(args, "POST", "/api/v1/campaigns", json=body)
    print(f"campaign {campaign['id']} {campaign['state']} on rig {campaign['rig']}")
    if args.watch:
        args.id = campaign["id"]
        return _watch(args)
    return EXIT_OK


@_guarded
def _control(args: argparse.Namespace) -> int:
    campaign = call(args, "POST", f"/api/v1/campaigns/{args.id}/{args.action}")
    pending = campaign.get("requested_action")
    note = f" ({pending} requested: at the next safe point)" if pending else ""
    print(f"campaign {campaign['id']} {campaign['state']}{note}")
    return EXIT_OK


@_guarded
def _list(args: argparse.Namespace) -> int:
    def row(c: dict[str, Any]) -> str:
        p = c["progress"]
        return (f"{c['id']:>5}  {c['state']:<10} {c['rig']:<10} {c['sensor']:<12} "
                f"{_step(p):>7}  {p['fraction']:>5.0%}")

    return print_listing(
        args, "/api/v1/campaigns",
        f"{'id':>5}  {'state':<10} {'rig':<10} {'sensor':<12} {'step':>7}  {'done':>5}", row,
        params={"state": args.state} if args.state else None)


def print_listing(args: argparse.Namespace, path: str, header: str,
                  row: Callable[[dict[str, Any]], str], *,
                  params: dict[str, Any] | None = None) -> int:
    """``GET path``: with ``--json`` the list as the API returned it, else ``header`` and
    one ``row(item)`` a line (``campaign list``, ``schedule list``)."""
    items = call(args, "GET", path, params=params)
    if args.json:
        print(json.dumps(items, indent=2))
        return EXIT_OK
    print(header)
    for item in items:
        print(row(item))
    return EXIT_OK


@_guarded
def _watch(args: argparse.Namespace) -> int:
    """Follow the SSE stream; fall back to polling if the stream breaks."""
    last: dict[str, Any] | None = None
    _last_drawn.clear()
    try:
        for campaign in _sse_campaigns(args):
            last = campaign
            _draw(campaign)
    except ApiError:
        raise
    except Exception:  # stream cut (proxy, restart): poll instead
        while last is None or last["state"] not in TERMINAL:
            last = call(args, "GET", f"/api/v1/campaigns/{args.id}")
            _draw(last)
            if last["state"] not in TERMINAL:
                time.sleep(1.0)
    if sys.stdout.isatty():
        sys.stdout.write("\n")  # end the line redrawn in place
    if last is None:
        return EXIT_FAILED
    if last.get("error"):
        print(f"error: {last['error']}")
    if last["state"] == "completed" and last.get("calibration_id") is not None:
        print(
            f"calibration {last['calibration_id']} of sensor {last['sensor']}: "
            f"soakcal coefficients {last['sensor']} --temperature-c T"
        )
    return EXIT_OK if last["state"] == "completed" else EXIT_FAILED


def _sse_campaigns(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    with (
        _client(args) as client,
        client.stream("GET", f"/api/v1/campaigns/{args.id}/events", timeout=None) as response,
    ):
        if response.status_code >= 400:
            response.read()
            raise ApiError(
                response.status_code, f"HTTP {response.status_code}: {_detail(response)}"
            )
        event, data = "message", []
        for line in response.iter_lines():
            if line.startswith("event:"):
                event = line[6:].strip()
            elif line.startswith("data:"):
                data.append(line[5:].strip())
            elif line == "":
                if event == "progress" and data:
                    yield json.loads("\n".join(data))
                event, data = "message", []


_last_drawn: list[str] = []  # the last line written to a non-terminal (one per change)


def _draw(campaign: dict[str, Any]) -> None:
    """The progress line: redrawn in place on a terminal; on a pipe or a log file one plain
    line whenever it changes (no carriage returns, no escape codes in the file)."""
    line = progress_line(campaign)
    if sys.stdout.isatty():
        sys.stdout.write("\r" + line + "\x1b[K")
    elif not _last_drawn or _last_drawn[-1] != line:
        sys.stdout.write(line + "\n")
        _last_drawn[:] = [line]
    sys.stdout.flush()


def progress_line(campaign: dict[str, Any], width: int = 24) -> str:
    """``[#####.....]  42% step 4 of 0..10 soak 12.3 °C → 10 °C  ETA 1h02m  running``.

    Steps are 0-based, as the API's ``progress.step`` and the recording's ``step`` column.
    """
    p = campaign["progress"]
    filled = int(round(p["fraction"] * width))
    bar = "#" * filled + "." * (width - filled)
    chamber = "–" if p.get("chamber_c") is None else f"{p['chamber_c']:.1f}"
    setpoint = "–" if p.get("setpoint_c") is None else f"{p['setpoint_c']:g}"
    return (
        f"[{bar}] {p['fraction']:4.0%} step {_step(p)} "
        f"{p['phase']:<9} {chamber} °C → {setpoint} °C  ETA {_eta(p.get('eta_s'))}  "
        f"{campaign['state']}"
    )


def _step(p: dict[str, Any]) -> str:
    """``4 of 0..10``: the 0-based step (clamped to the last) and the range."""
    last = max(p["steps"] - 1, 0)
    return f"{min(p['step'], last)} of 0..{last}"


def _eta(eta_s: float | None) -> str:
    if eta_s is None:
        return "?"
    minutes = int(eta_s // 60)
    return (
        f"{minutes // 60}h{minutes % 60:02d}m"
        if minutes >= 60
        else f"{minutes}m{int(eta_s % 60):02d}s"
    )
