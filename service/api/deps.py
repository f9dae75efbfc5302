"""Request-scoped dependencies: a database session from the app's session factory.

Why sessions are admitted through a semaphore: sync handlers run on Starlette's
40-thread pool and FastAPI validates their response on that pool while the
request's session still holds a connection. If more requests want connections
than the pool has, threads block in ``pool.connect()`` while the connections'
holders wait for a free thread to validate their responses: every request
stalls until the 30 s pool timeout and fails with 500 (reproduced with 200
concurrent ``GET /api/v1/rigs``). Waiting for a slot *on the event loop*,
before any thread is taken, with fewer slots than pooled connections, means no
thread ever waits for a connection, so the cycle cannot form; excess requests
simply queue.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import Depends, Path, Request
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from calibration.campaign_spec import SERIAL_PATTERN
from service.db.session import POOL_MAX_OVERFLOW, POOL_SIZE

# Leave connections for the campaign engine, the scheduler and the event streams.
REQUEST_DB_SLOTS = POOL_SIZE + POOL_MAX_OVERFLOW - 15


@contextlib.asynccontextmanager
async def db_slot(request: Request) -> AsyncIterator[None]:
    """Hold one of the app's request database slots (created with the app's first use)."""
    slots = getattr(request.app.state, "db_slots", None)
    if slots is None:
        import asyncio

        slots = request.app.state.db_slots = asyncio.Semaphore(REQUEST_DB_SLOTS)
    async with slots:
        yield


async def get_session(request: Request) -> AsyncIterator[Session]:
    """One session per request; handlers commit what they change."""
    async with db_slot(request):
        session = request.app.state.session_factory()
        try:
            yield session
        finally:
            await run_in_threadpool(session.close)


SessionDep = Annotated[Session, Depends(get_session)]


# Database ids are 32-bit signed on PostgreSQL (and 64-bit on SQLite): bounded here, an
# out-of-range id is a 422 naming the path parameter, never a driver overflow (500).
MAX_DB_ID = 2**31 - 1
DbIdPath = Annotated[int, Path(ge=1, le=MAX_DB_ID, description="a database id, 1..2^31-1")]
# Sensor serials travel in URL paths: SERIAL_PATTERN is the campaign spec's serial pattern.
SerialPath = Annotated[str, Path(pattern=SERIAL_PATTERN, max_length=64,
                                 description="sensor serial: letters, digits and _ . : -")]
