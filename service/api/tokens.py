"""``/api/v1/tokens`` (admin): create tokens over HTTP, like ``soakcal token create``."""

from __future__ import annotations

from fastapi import APIRouter, Depends

from service.api import auth
from service.api.deps import SessionDep
from service.api.schemas import TokenCreate, TokenCreated
from service.db.models import ApiToken

router = APIRouter(prefix="/api/v1/tokens", tags=["tokens"], dependencies=[Depends(auth.admin)])


@router.post("", response_model=TokenCreated, status_code=201)
def create(body: TokenCreate, session: SessionDep) -> TokenCreated:
    token = auth.create_token(session, body.role, body.name)
    row = session.query(ApiToken).filter_by(token_hash=auth.hash_token(token)).one()
    session.commit()
    return TokenCreated(id=row.id, role=body.role, name=body.name, token=token)
