"""``/api/v1/health``: no auth, so load balancers and compose healthchecks can call it."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from sqlalchemy import text

from service.api.schemas import HealthOut
from service.config import service_version

router = APIRouter(prefix="/api/v1", tags=["health"])


@router.get(
    "/health",
    response_model=HealthOut,
    responses={503: {"model": HealthOut, "description": "the database does not answer"}},
)
def health(request: Request) -> JSONResponse:
    database_ok = _database_answers(request)
    body = HealthOut(
        status="ok" if database_ok else "error",
        database="ok" if database_ok else "error",
        version=service_version(),
    )
    return JSONResponse(body.model_dump(), status_code=200 if database_ok else 503)


def _database_answers(request: Request) -> bool:
    try:
        with request.app.state.session_factory() as session:
            session.execute(text("SELECT 1"))
        return True
    except Exception:  # any driver error means "not answering" to a health probe
        return False
