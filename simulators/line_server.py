"""One loopback TCP server for the twins that answer a line protocol (the ESPEC controller,
the sensor bridge): each connection is its own task, served until it closes, and stopping
the server cancels every connection still open, so a test's teardown never waits on one."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

ServeClient = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


@dataclass
class LineServer:
    server: asyncio.base_events.Server
    host: str
    port: int
    _tasks: set[asyncio.Task] = field(default_factory=set)

    async def stop(self) -> None:
        self.server.close()
        for t in list(self._tasks):
            t.cancel()
        with contextlib.suppress(Exception):
            await self.server.wait_closed()


async def start_line_server(serve_client: ServeClient, *, host: str = "127.0.0.1",
                            port: int = 0) -> LineServer:
    """Listen on ``host:port`` (0: any free port); ``serve_client`` answers one connection
    and returns when it ends; the writer is closed after it in every case."""
    tasks: set[asyncio.Task] = set()

    async def on_client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            tasks.add(task)
        try:
            await serve_client(reader, writer)
        finally:
            if task is not None:
                tasks.discard(task)
            writer.close()

    server = await asyncio.start_server(on_client, host, port)
    return LineServer(server, host, server.sockets[0].getsockname()[1], tasks)
