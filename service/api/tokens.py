"""``/api/v1/tokens`` (admin): create, list and revoke tokens, like ``soakcal token ...``."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, HTTPException, Path, Response
from pydantic import BaseModel, Field
from sqlalchemy import select

from service.api import auth
from service.api.deps import SessionDep
from service.api.schemas import TokenCreate, TokenCreated
from service.db.models import ApiToken
from service.db.timestamps import as_utc, utcnow
from service.event_log import log_event

_AUTH = {
    401: {"description": "missing, unknown, revoked or expired token"},
    403: {"description": "the token's role is below admin"},
}
router = APIRouter(
    prefix="/api/v1/tokens", tags=["tokens"], dependencies=[Depends(auth.admin)], responses=_AUTH
)

TokenId = Annotated[int, Path(ge=1, le=2**31 - 1, description="the token's id")]


class TokenCreateBody(TokenCreate):
    expires_days: float | None = Field(
        default=None,
        strict=True,  # a JSON number: true or "30" is a 422, not 1 or 30 days
        gt=0,
        le=auth.MAX_EXPIRES_DAYS,
        description="refused (401) after this many days; omitted: never expires",
    )


class TokenOut(BaseModel):
    """A token's metadata; the token itself is never shown again after creation."""

    id: int
    name: str | None
    role: str
    status: Literal["active", "revoked", "expired"]
    created_at: dt.datetime
    last_used_at: dt.datetime | None = Field(
        description="last request with this token (updated at most once a minute)"
    )
    expires_at: dt.datetime | None
    revoked_at: dt.datetime | None


def token_out(row: ApiToken, now: dt.datetime | None = None) -> TokenOut:
    return TokenOut(
        id=row.id,
        name=row.name,
        role=row.role,
        status=auth.token_status(row, now),  # type: ignore[arg-type]
        created_at=as_utc(row.created_at),  # type: ignore[arg-type]
        last_used_at=as_utc(row.last_used_at),
        expires_at=as_utc(row.expires_at),
        revoked_at=as_utc(row.revoked_at),
    )


@router.post("", response_model=TokenCreated, status_code=201)
def create(body: TokenCreateBody, session: SessionDep) -> TokenCreated:
    token = auth.create_token(session, body.role, body.name, body.expires_days)
    row = session.query(ApiToken).filter_by(token_hash=auth.hash_token(token)).one()
    session.commit()
    log_event("token created", token_id=row.id, role=body.role, name=body.name)
    return TokenCreated(id=row.id, role=body.role, name=body.name, token=token)


@router.get("", response_model=list[TokenOut])
def list_tokens(session: SessionDep) -> list[TokenOut]:
    """Every token, newest first, with its status (active, revoked, expired)."""
    now = utcnow()
    return [token_out(r, now) for r in session.scalars(select(ApiToken).order_by(ApiToken.id))]


@router.delete(
    "/{token_id}", status_code=204, responses={404: {"description": "no such token"}}
)
def revoke(token_id: TokenId, session: SessionDep) -> Response:
    """Revoke a token: its next request gets 401. Revoking twice is not an error."""
    row = session.get(ApiToken, token_id)
    if row is None:
        raise HTTPException(status_code=404, detail=f"token {token_id} not found")
    if row.revoked_at is None:
        row.revoked_at = utcnow()
        session.commit()
        log_event("token revoked", token_id=token_id, role=row.role, name=row.name)
    return Response(status_code=204)
