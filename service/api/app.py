"""The FastAPI application factory and its lifespan (migrations, seed, scheduler, engine)."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from service import web
from service.api import calibrations, campaigns, door, fleet, health, rigs, schedules, tokens
from service.api import placement as placement_api  # manual fixtures (issue 9)
from service.campaigns import load_rigs_file, seed_sim_rig, upsert_rigs
from service.config import Settings, service_version
from service.db.session import make_engine, make_session_factory, session_scope, upgrade_database
from service.engine.states import IllegalTransition
from service.scheduler import Scheduler

log = logging.getLogger(__name__)

DESCRIPTION = """Thermal-soak calibration campaigns for triaxial MEMS accelerometers.

Every call except `GET /api/v1/health` needs `Authorization: Bearer <token>`
(`soakcal token create --role viewer|operator|admin`)."""


def create_app(settings: Settings | None = None) -> FastAPI:
    """The REST service of docs/rest-contract.md over ``settings.database_url``."""
    settings = settings or Settings()
    engine = make_engine(settings.database_url)
    app = FastAPI(
        title="soakcal",
        version=service_version(),
        description=DESCRIPTION,
        lifespan=_lifespan,
        docs_url=None,  # service.web serves /docs and /redoc with packaged assets (no CDN)
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.session_factory = make_session_factory(engine)
    for module in (health, rigs, campaigns, calibrations, schedules, tokens, fleet):
        app.include_router(module.router)
    app.include_router(placement_api.router)
    app.include_router(web.router)
    web.mount_static(app)
    web.add_cors(app)
    app.add_exception_handler(IllegalTransition, _conflict)
    # The door (service/api/door.py): body limit before parsing, 401 before 422, short 422s,
    # 401/403/413 in the OpenAPI document.
    app.add_exception_handler(RequestValidationError, door.validation_error_handler)
    app.add_middleware(door.BodyLimitMiddleware, max_body_bytes=settings.max_body_bytes,
                       authenticated=door.bearer_check(app))
    app.add_middleware(door.AllowHeaderMiddleware, openapi=lambda: app.openapi())
    door.document_auth_responses(app)
    return app


async def _conflict(_request: Request, exc: Exception) -> JSONResponse:
    """The state machine's refusal (``service.engine.states``) as HTTP 409."""
    return JSONResponse({"detail": str(exc)}, status_code=409)


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings
    factory = app.state.session_factory
    if settings.migrate:
        await run_in_threadpool(upgrade_database, settings.database_url)
    if settings.seed_sim_rig:
        await run_in_threadpool(_seed, factory)
    if settings.rigs_file:
        # Read before anything runs: a bad file stops the start with its name and field.
        rig_configs = load_rigs_file(settings.rigs_file)
        names = await run_in_threadpool(_upsert, factory, rig_configs)
        log.info("rigs from %s: %s", settings.rigs_file, ", ".join(names) or "unchanged")
    background: list[Any] = []
    try:
        if settings.run_scheduler:
            scheduler = Scheduler(factory, interval_s=settings.scheduler_interval_s)
            await scheduler.start()
            background.append(scheduler)
        if settings.run_engine:
            manager = _campaign_manager(settings, factory)
            if manager is not None:
                await manager.start()
                background.append(manager)
        app.state.background = background
        yield
    finally:
        for worker in reversed(background):
            await worker.stop()
        app.state.engine.dispose()


def _seed(factory: Any) -> None:
    with session_scope(factory) as session:
        seed_sim_rig(session)


def _upsert(factory: Any, rig_configs: list[dict[str, Any]]) -> list[str]:
    with session_scope(factory) as session:
        return upsert_rigs(session, rig_configs)


def _campaign_manager(settings: Settings, factory: Any) -> Any | None:
    """The campaign runner manager, imported lazily: the API works without the engine."""
    try:
        from service.engine.manager import CampaignManager
    except ImportError as exc:
        log.error("campaign engine unavailable (%s): campaigns will stay queued", exc)
        return None
    if settings.engine_rigs == frozenset():  # serve --rigs none: the API alone
        return None
    only = {} if settings.engine_rigs is None else {"rigs": settings.engine_rigs}
    return CampaignManager(factory, sim_speed=settings.sim_speed, owner=settings.engine_owner,
                           **only)
