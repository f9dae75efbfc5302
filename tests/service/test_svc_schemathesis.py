"""Schemathesis against /openapi.json, in-process (ASGI): no 5xx, nothing outside the schema,
on SQLite and (with SOAKCAL_TEST_DATABASE_URL) on PostgreSQL.

Bounded so the suite stays fast: examples, coverage and fuzzing phases with at most
``MAX_EXAMPLES`` generated cases per operation, then a short stateful run over the links
Schemathesis infers (create a campaign, then read, pause, abort it). An admin token is
sent on every case (the coverage phase also drops it to check 401s); the auth paths
themselves are tested in test_svc_door.py.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from pg_schemas import new_schema_name, postgres_schema, postgres_schema_url

schemathesis = pytest.importorskip("schemathesis")
from hypothesis import HealthCheck, settings  # noqa: E402

# No example database: Hypothesis otherwise keeps examples under .hypothesis/ in the working
# tree and replays them first on the next run, where the app's state differs, so the stateful
# run failed with "Inconsistent data generation" (FlakyStrategyDefinition) after 300 s on a
# second `make test` in the same checkout, and passed every time without the saved examples.
settings.register_profile("soakcal-no-example-db", database=None)
settings.load_profile("soakcal-no-example-db")
from schemathesis.checks import not_a_server_error  # noqa: E402
from schemathesis.specs.openapi.checks import (  # noqa: E402
    content_type_conformance,
    positive_data_acceptance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)
from sqlalchemy import delete  # noqa: E402

from service.api.app import create_app  # noqa: E402
from service.api.auth import create_token, hash_token  # noqa: E402
from service.campaigns import seed_sim_rig  # noqa: E402
from service.config import Settings  # noqa: E402
from service.db.models import Base  # noqa: E402
from service.db.session import session_scope, upgrade_database  # noqa: E402

POSTGRES_ENV = "SOAKCAL_TEST_DATABASE_URL"

MAX_EXAMPLES = 10
# Every built-in check runs (no 5xx, status codes, content types, bodies and headers as
# documented, Allow on 405, negative data rejected, auth not ignored, …) except one:
# positive_data_acceptance expects every schema-valid body to be accepted, and the dry run
# refuses schema-valid campaigns by design ("positions": "sphere1", a setpoint outside the
# rig's chamber, an unknown cron or time zone).
EXCLUDED = [positive_data_acceptance]
# The stateful phase validates with the same set: the base checks plus these.
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance,
          response_schema_conformance, response_headers_conformance]


class _Target:
    """One in-process app on one database, and its schema for schemathesis.

    Built at import (schemathesis parametrizes at collection); the database is created
    lazily by :meth:`admin_headers`, so collecting this module opens nothing.
    """

    def __init__(self, url: str) -> None:
        self.url = url
        self.app = create_app(Settings(database_url=url, run_engine=False, run_scheduler=False,
                                       migrate=False, seed_sim_rig=False, events_poll_s=0.01))
        # The event stream never ends while a campaign is not terminal: one GET would hang.
        self.schema = schemathesis.openapi.from_asgi(
            "/openapi.json", self.app, config=_CONFIG).exclude(path_regex=r"/events$")

    def admin_headers(self) -> dict[str, str]:
        upgrade_database(self.url)
        with session_scope(self.app.state.session_factory) as session:
            seed_sim_rig(session)
            token = create_token(session, "admin", "schemathesis")
        return {"Authorization": f"Bearer {token}"}

    def reset(self, admin_headers: dict[str, str]) -> None:
        """Every row but the admin's token gone, the simulated rig seeded again: what a
        request returns must not depend on what an earlier scenario left (a campaign still
        queued on the rig turns the next POST into a 409), or Hypothesis, replaying a
        scenario, finds it draws differently and fails as "flaky" (FlakyStrategyDefinition)."""
        admin_hash = hash_token(admin_headers["Authorization"].removeprefix("Bearer "))
        with session_scope(self.app.state.session_factory) as session:
            for table in reversed(Base.metadata.sorted_tables):
                if table.name == "api_tokens":
                    session.execute(delete(table).where(table.c.token_hash != admin_hash))
                    session.execute(table.update().values(revoked_at=None, expires_at=None))
                else:
                    session.execute(delete(table))
            seed_sim_rig(session)


_CONFIG = schemathesis.config.SchemathesisConfig.from_dict({
    "seed": 20261123,
    "generation": {"max-examples": MAX_EXAMPLES},
    "phases": {"examples": {"enabled": True}, "coverage": {"enabled": True},
               "fuzzing": {"enabled": True}, "stateful": {"enabled": True, "max-steps": 8}},
})
_DB_DIR = Path(tempfile.mkdtemp(prefix="soakcal-schemathesis-"))
SQLITE = _Target(f"sqlite:///{_DB_DIR / 'soakcal.db'}")
# PostgreSQL too when the suite has one: it refuses what SQLite stores (a NUL character in
# text, NaN in JSON), so a 500 may hide on one database only. Its own schema (random name).
_PG_BASE = os.environ.get(POSTGRES_ENV)
_PG_SCHEMA = new_schema_name()
POSTGRES = _Target(postgres_schema_url(_PG_BASE, _PG_SCHEMA)) if _PG_BASE else None


@pytest.fixture(scope="module")
def sqlite_admin() -> Iterator[dict[str, str]]:
    yield SQLITE.admin_headers()
    SQLITE.app.state.engine.dispose()
    shutil.rmtree(_DB_DIR, ignore_errors=True)


@pytest.fixture(scope="module")
def postgres_admin() -> Iterator[dict[str, str]]:
    if POSTGRES is None or _PG_BASE is None:
        pytest.skip(f"{POSTGRES_ENV} not set")
    schema = postgres_schema(_PG_BASE, _PG_SCHEMA)
    next(schema)  # created
    try:
        yield POSTGRES.admin_headers()
    finally:
        POSTGRES.app.state.engine.dispose()
        schema.close()  # dropped


@SQLITE.schema.parametrize()
@settings(deadline=None, suppress_health_check=list(HealthCheck))
def test_the_api_honours_its_schema(case, sqlite_admin: dict[str, str]) -> None:  # type: ignore[no-untyped-def]
    case.call_and_validate(headers=sqlite_admin, excluded_checks=EXCLUDED)


if POSTGRES is not None:
    @POSTGRES.schema.parametrize()
    @settings(deadline=None, suppress_health_check=list(HealthCheck))
    def test_the_api_honours_its_schema_on_postgresql(case, postgres_admin: dict[str, str]) -> None:  # type: ignore[no-untyped-def]
        case.call_and_validate(headers=postgres_admin, excluded_checks=EXCLUDED)
else:
    def test_the_api_honours_its_schema_on_postgresql() -> None:
        pytest.skip(f"{POSTGRES_ENV} not set")


def _stateful(target: _Target, admin_headers: dict[str, str]) -> None:
    """The stateful phase: chains such as POST /campaigns → GET/pause/abort that campaign."""
    base = target.schema.as_state_machine()

    class Machine(base):  # type: ignore[misc, valid-type]
        def setup(self) -> None:
            target.reset(admin_headers)

        def get_call_kwargs(self, case):  # type: ignore[no-untyped-def]
            return {"headers": admin_headers}

        def validate_response(self, response, case, additional_checks=None, **kwargs):  # type: ignore[no-untyped-def]
            case.validate_response(response, checks=CHECKS)

    Machine.run(settings=settings(max_examples=8, stateful_step_count=6, deadline=None,
                                  suppress_health_check=list(HealthCheck)))


def test_stateful_sequences_over_the_inferred_links(sqlite_admin: dict[str, str]) -> None:
    _stateful(SQLITE, sqlite_admin)


def test_stateful_sequences_on_postgresql(postgres_admin: dict[str, str]) -> None:
    assert POSTGRES is not None
    _stateful(POSTGRES, postgres_admin)
