"""Bearer-token auth with three ordered roles: viewer < operator < admin.

Only a SHA-256 of each token is stored. That is enough here (no salt, no slow
KDF) because tokens are 256-bit random strings we generate ourselves, not
human passwords: nothing to brute-force or look up in a dictionary, and a
fast hash keeps per-request checks cheap. A leaked database therefore does
not leak usable tokens.
"""

from __future__ import annotations

import hashlib
import secrets
from collections.abc import Awaitable, Callable
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy import select
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from service.api.deps import db_slot
from service.db.models import ApiToken

ROLES: tuple[str, ...] = ("viewer", "operator", "admin")
TOKEN_PREFIX = "sct_"

_bearer = HTTPBearer(auto_error=False, description="`soakcal token create --role ROLE`")


def create_token(session: Session, role: str, name: str | None = None) -> str:
    """Store a new token's hash with ``role``; return the token (shown once, never stored)."""
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; expected one of {', '.join(ROLES)}")
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    session.add(ApiToken(name=name, role=role, token_hash=hash_token(token)))
    session.flush()
    return token


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def role_at_least(role: str, minimum: str) -> bool:
    return ROLES.index(role) >= ROLES.index(minimum)


def require_role(minimum: str) -> Callable[..., Awaitable[ApiToken]]:
    """A dependency that admits tokens of role ``minimum`` or higher (401 / 403 otherwise)."""
    if minimum not in ROLES:
        raise ValueError(f"unknown role {minimum!r}")

    async def dependency(
        request: Request,
        credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
    ) -> ApiToken:
        if credentials is None or credentials.scheme.lower() != "bearer":
            raise _unauthorized("missing bearer token (Authorization: Bearer <token>)")
        token_hash = hash_token(credentials.credentials)

        def lookup() -> ApiToken | None:
            with request.app.state.session_factory() as session:
                return session.scalar(select(ApiToken).where(ApiToken.token_hash == token_hash))

        async with db_slot(request):  # see service/api/deps.py for why
            row = await run_in_threadpool(lookup)
        if row is None:
            raise _unauthorized("unknown token")
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
