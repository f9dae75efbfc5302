"""Which rigs this process drives: ``serve --rigs`` and ``soakcal worker`` (engine, no HTTP).

Serial lines and RTU buses hang off one host, so a lab with rigs on several
hosts runs one process per host, each naming its rigs; all of them share one
PostgreSQL database, whose rig leases (service/engine/manager.py) and fenced
measurement commits (service/engine/store.py) keep two processes from ever
driving one rig. See docs/engine.md, "Rigs on several hosts".
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys

from service.config import parse_rigs


def rigs_argument(text: str) -> str:
    """argparse type for ``--rigs``: validated, kept as text (one-line error, exit 2)."""
    try:
        parse_rigs(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def run_worker(args: argparse.Namespace) -> int:
    """``soakcal worker --rigs …``: the campaign engine for those rigs until SIGINT/SIGTERM."""
    from service.config import resolve_database_url
    from service.db.session import make_session_factory, upgrade_database

    rigs = parse_rigs(args.rigs)
    if rigs == frozenset():
        print("soakcal worker: --rigs none leaves nothing to run", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    url = resolve_database_url()
    upgrade_database(url)
    factory = make_session_factory(url)
    try:
        asyncio.run(_serve_rigs(factory, rigs, args.sim_speed))
    finally:
        factory.kw["bind"].dispose()
    return 0


async def _serve_rigs(factory: object, rigs: frozenset[str] | None, sim_speed: float) -> None:
    from service.engine.manager import CampaignManager

    manager = CampaignManager(factory, sim_speed=sim_speed, rigs=rigs)  # type: ignore[arg-type]
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    await manager.start()
    logging.getLogger(__name__).info(
        "engine for rigs: %s", "every rig" if rigs is None else ", ".join(sorted(rigs)))
    try:
        await stop.wait()
    finally:
        # Cancels every run: each parks its rig and leaves its campaign to the next holder.
        await manager.stop()
