"""Engine test fixtures: a session factory on a migrated database.

``migrated_db_url`` (tests/conftest.py) runs each test on SQLite, and on
PostgreSQL too when SOAKCAL_TEST_DATABASE_URL is set.
"""

from __future__ import annotations

import pytest

from service.db.session import make_session_factory
from service.engine.store import fast_sqlite_commits


@pytest.fixture
def sf(migrated_db_url: str):  # type: ignore[no-untyped-def]
    factory = make_session_factory(migrated_db_url)
    fast_sqlite_commits(factory)
    yield factory
    factory.kw["bind"].dispose()
