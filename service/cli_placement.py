"""``soakcal campaign place ID [--position K]`` and the placement lines of ``campaign watch``.

A rig with a manual turntable (docs/manual-fixtures.md) waits for the operator
to place the sensor by hand. ``place`` confirms the pending placement over REST
(``POST /api/v1/campaigns/{id}/placement``); without ``--position`` it confirms
whatever position is asked now. ``watch`` keeps its progress line and, while it
runs, prints each new placement request (instruction, sketch, and the reason
when the engine re-asked) on lines of their own.
"""

from __future__ import annotations

import argparse
import sys
import threading
from typing import Any

from service.cli_campaign import ApiError, _watch, call, client_options, guarded

EXIT_OK = 0
WATCH_POLL_S = 2.0  # wall seconds between two placement reads while watching

_guarded = guarded("campaign place")


def add_placement_parser(actions: Any) -> None:
    """Register ``place`` and give ``watch`` the placement printer (one call from cli_campaign)."""
    place = actions.add_parser("place", parents=[client_options()],
                               help="confirm a hand placement (manual turntable)")
    place.add_argument("id", type=int)
    place.add_argument("--position", type=int, default=None,
                       help="schedule index placed (default: the one asked now)")
    place.set_defaults(handler=_place)
    watch = actions.choices.get("watch")
    if watch is not None:
        watch.set_defaults(handler=_watch_with_placement)


def describe_request(request: dict[str, Any]) -> str:
    """The lines an operator reads for one request."""
    lines = [f"placement of position {request['position']} asked "
             f"(request {request['seq']}, {request['state']}): {request['instruction']}"]
    if request.get("reason"):
        lines.append(f"re-asked: {request['reason']}")
    lines.append(request["sketch"])
    lines.append(f"when placed: soakcal campaign place {request['campaign_id']} "
                 f"--position {request['position']}")
    return "\n".join(lines)


@_guarded
def _place(args: argparse.Namespace) -> int:
    position = args.position
    if position is None:
        now = call(args, "GET", f"/api/v1/campaigns/{args.id}/placement")
        request = now.get("request")
        if request is None or request["state"] != "pending":
            raise ApiError(409, f"campaign {args.id}: no placement is pending")
        position = request["position"]
    done = call(args, "POST", f"/api/v1/campaigns/{args.id}/placement",
                json={"position": position})
    request = done["request"]
    print(f"campaign {args.id}: position {request['position']} confirmed "
          f"({request['instruction']}); the engine checks it with a short capture")
    return EXIT_OK


def _watch_with_placement(args: argparse.Namespace) -> int:
    """``campaign watch`` plus a thread that prints each new pending placement request."""
    stop = threading.Event()
    printer = threading.Thread(target=_print_requests, args=(args, stop), daemon=True)
    printer.start()
    try:
        return int(_watch(args))
    finally:
        stop.set()
        printer.join(timeout=WATCH_POLL_S + 1.0)


def _print_requests(args: argparse.Namespace, stop: threading.Event) -> None:
    shown: tuple[int, int] | None = None
    while not stop.is_set():
        try:
            now = call(args, "GET", f"/api/v1/campaigns/{args.id}/placement")
        except ApiError:  # 404 (old service) or a dropped link: the progress line goes on
            now = {}
        request = now.get("request") if now.get("campaign_state") == "running" else None
        if request and request["state"] == "pending" and (request["campaign_id"],
                                                         request["seq"]) != shown:
            shown = (request["campaign_id"], request["seq"])
            sys.stdout.write("\n" + describe_request(request) + "\n")
            sys.stdout.flush()
        stop.wait(WATCH_POLL_S)
