"""Sign-in for the dashboard: a token exchanged for an HttpOnly, SameSite=Strict cookie.

``EventSource`` cannot send an ``Authorization`` header, so the page keeps
the token in a cookie the page's scripts cannot read (HttpOnly) and that
the browser never sends with a cross-site request (SameSite=Strict).
``service.api.auth`` accepts the cookie wherever it accepts a bearer token
and asks a cookie-authenticated change for the ``X-Soakcal-CSRF`` header.
The REST API keeps bearer tokens: nothing here is needed by ``curl``.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Request, Response
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from service.api import auth
from service.api.deps import db_slot
from service.db.models import ApiToken
from service.db.timestamps import as_utc, utcnow

# A browser session lasts a working day at most (and never beyond the token's expiry).
SESSION_MAX_AGE_S = 12 * 3600

router = APIRouter(prefix="/web", tags=["dashboard"])


class SignIn(BaseModel):
    token: str = Field(min_length=1, max_length=256, description="an API token (sct_...)")


class WhoAmI(BaseModel):
    role: str
    name: str | None
    token_id: int


@router.post(
    "/session",
    response_model=WhoAmI,
    responses={
        401: {"description": "unknown, revoked or expired token"},
        403: {"description": "without the X-Soakcal-CSRF header, or from another origin"},
    },
)
async def sign_in(body: SignIn, request: Request, response: Response) -> WhoAmI:
    """Check the token and keep it in the session cookie."""
    auth.check_csrf(request, "sign-in")

    def lookup() -> ApiToken:
        with request.app.state.session_factory() as session:
            return auth.check_token(session, body.token)

    async with db_slot(request):
        row = await run_in_threadpool(lookup)
    max_age = SESSION_MAX_AGE_S
    expires_at = as_utc(row.expires_at)
    if expires_at is not None:
        max_age = max(1, min(max_age, int((expires_at - utcnow()).total_seconds())))
    response.set_cookie(
        auth.SESSION_COOKIE,
        body.token,
        max_age=max_age,
        path="/",
        httponly=True,
        samesite="strict",
        secure=request.url.scheme == "https",
    )
    return WhoAmI(role=row.role, name=row.name, token_id=row.id)


@router.get(
    "/session", response_model=WhoAmI, responses={401: {"description": "not signed in"}}
)
async def who_am_i(row: Annotated[ApiToken, Depends(auth.viewer)]) -> WhoAmI:
    """The signed-in token's role (401 when the cookie is missing, revoked or expired)."""
    return WhoAmI(role=row.role, name=row.name, token_id=row.id)


@router.delete(
    "/session", status_code=204, responses={403: {"description": "without X-Soakcal-CSRF"}}
)
async def sign_out(request: Request) -> Response:
    auth.check_csrf(request, "sign-out")
    response = Response(status_code=204)
    response.delete_cookie(auth.SESSION_COOKIE, path="/", httponly=True, samesite="strict")
    return response
