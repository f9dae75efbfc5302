"""Bearer-token auth with three ordered roles: viewer < operator < admin.

Only a SHA-256 of each token is stored. That is enough here (no salt, no slow
KDF) because tokens are 256-bit random strings we generate ourselves, not
human passwords: nothing to brute-force or look up in a dictionary, and a
fast hash keeps per-request checks cheap. A leaked database therefore does
not leak usable tokens.

A token may carry an expiry and may be revoked; either makes it 401 on its
next request (the row is read on every request, nothing is cached).

Browsers: the dashboard (``service.web``) keeps the token in an HttpOnly,
SameSite=Strict cookie (:data:`SESSION_COOKIE`) because ``EventSource``
cannot send an ``Authorization`` header. A cookie-authenticated request that
changes state must also carry :data:`CSRF_HEADER` (a custom header, which a
cross-site form or image cannot set, and a cross-site script cannot set
without a CORS preflight that the service does not grant) and, when the
browser sends ``Origin``, an origin equal to the service's own.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import secrets
from collections.abc import Awaitable, Callable
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy import select, update
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from service.api.deps import db_slot
from service.db.models import ApiToken
from service.db.timestamps import as_utc, utcnow

ROLES: tuple[str, ...] = ("viewer", "operator", "admin")
TOKEN_PREFIX = "sct_"
SESSION_COOKIE = "soakcal_session"
CSRF_HEADER = "X-Soakcal-CSRF"
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
# last_used_at is written at most this often per token: a write on every request would
# serialise readers on SQLite for a value nobody needs to the second.
LAST_USED_RESOLUTION_S = 60.0
MAX_EXPIRES_DAYS = 3650

_bearer = HTTPBearer(auto_error=False, description="`soakcal token create --role ROLE`")


def create_token(
    session: Session, role: str, name: str | None = None, expires_days: float | None = None
) -> str:
    """Store a new token's hash with ``role``; return the token (shown once, never stored).

    ``expires_days``: the token is refused after that many days (None: never expires).
    """
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; expected one of {', '.join(ROLES)}")
    expires_at = None
    if expires_days is not None:
        if not 0 < expires_days <= MAX_EXPIRES_DAYS:
            raise ValueError(f"expires_days must be in (0, {MAX_EXPIRES_DAYS}], got {expires_days}")
        expires_at = utcnow() + dt.timedelta(days=expires_days)
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    session.add(
        ApiToken(name=name, role=role, token_hash=hash_token(token), expires_at=expires_at)
    )
    session.flush()
    return token


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def role_at_least(role: str, minimum: str) -> bool:
    return ROLES.index(role) >= ROLES.index(minimum)


def token_status(row: ApiToken, now: dt.datetime | None = None) -> str:
    """``active``, ``revoked`` or ``expired`` (revocation wins: it was a deliberate act)."""
    now = now or utcnow()
    if row.revoked_at is not None:
        return "revoked"
    expires_at = as_utc(row.expires_at)
    if expires_at is not None and expires_at <= now:
        return "expired"
    return "active"


def check_token(session: Session, token: str) -> ApiToken:
    """The active token row for ``token`` (``last_used_at`` refreshed), else HTTP 401."""
    row = session.scalar(select(ApiToken).where(ApiToken.token_hash == hash_token(token)))
    if row is None:
        raise _unauthorized("unknown token")
    now = utcnow()
    status = token_status(row, now)
    if status != "active":
        raise _unauthorized(f"token {status}")
    last = as_utc(row.last_used_at)
    if last is None or (now - last).total_seconds() >= LAST_USED_RESOLUTION_S:
        session.execute(update(ApiToken).where(ApiToken.id == row.id).values(last_used_at=now))
        session.commit()
        row.last_used_at = now
    session.expunge(row)
    return row


def request_token(
    request: Request, credentials: HTTPAuthorizationCredentials | None
) -> tuple[str, bool]:
    """The presented token and whether it came from the dashboard's cookie (401 if none)."""
    if credentials is not None and credentials.scheme.lower() == "bearer":
        return credentials.credentials, False
    cookie = request.cookies.get(SESSION_COOKIE)
    if cookie:
        if request.method not in SAFE_METHODS:
            check_csrf(request, "cookie-authenticated change")
        return cookie, True
    raise _unauthorized("missing bearer token (Authorization: Bearer <token>)")


def check_csrf(request: Request, what: str) -> None:
    """403 unless the request carries :data:`CSRF_HEADER` and, when the browser sends
    ``Origin``, the service's own origin (sign-in and sign-out included: another site's
    page must not sign a browser in or out)."""
    if not request.headers.get(CSRF_HEADER):
        raise HTTPException(status_code=403, detail=f"{what} without the {CSRF_HEADER} header")
    origin = request.headers.get("origin")
    if origin is not None:
        own = f"{request.url.scheme}://{request.url.netloc}"
        if origin != own:
            raise HTTPException(status_code=403, detail=f"cross-origin request from {origin[:80]}")


def require_role(minimum: str) -> Callable[..., Awaitable[ApiToken]]:
    """A dependency that admits tokens of role ``minimum`` or higher (401 / 403 otherwise)."""
    if minimum not in ROLES:
        raise ValueError(f"unknown role {minimum!r}")

    async def dependency(
        request: Request,
        credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    ) -> ApiToken:
        token, _from_cookie = request_token(request, credentials)

        def lookup() -> ApiToken:
            with request.app.state.session_factory() as session:
                return check_token(session, token)

        async with db_slot(request):  # see service/api/deps.py for why
            row = await run_in_threadpool(lookup)
        if not role_at_least(row.role, minimum):
            raise HTTPException(
                status_code=403,
                detail=f"this action needs role '{minimum}' or higher; the token has '{row.role}'",
            )
        return row

    return dependency


def _unauthorized(detail: str) -> HTTPException:
    return HTTPException(status_code=401, detail=detail, headers={"WWW-Authenticate": "Bearer"})


viewer = require_role("viewer")
operator = require_role("operator")
admin = require_role("admin")
