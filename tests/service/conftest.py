"""Service test fixtures: an app on ``clean_db_url`` with the engine and scheduler off.

The tests play the runner's part by writing campaign rows directly, the way
another process would.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from service.api.app import create_app
from service.api.auth import create_token
from service.config import Settings
from service.db.session import session_scope


@pytest.fixture
def settings(clean_db_url: str) -> Settings:
    return Settings(
        database_url=clean_db_url,
        run_engine=False,
        run_scheduler=False,
        events_poll_s=0.02,
        migrate=False,  # clean_db_url is migrated already
    )


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    with TestClient(create_app(settings)) as test_client:
        yield test_client


@pytest.fixture
def sf(client: TestClient) -> sessionmaker[Session]:
    """The app's own session factory (same database, same pragmas)."""
    return client.app.state.session_factory  # type: ignore[attr-defined]


@pytest.fixture
def auth(sf: sessionmaker[Session]) -> dict[str, dict[str, str]]:
    """``Authorization`` headers per role."""
    headers = {}
    with session_scope(sf) as session:
        for role in ("viewer", "operator", "admin"):
            headers[role] = {"Authorization": f"Bearer {create_token(session, role, role)}"}
    return headers
