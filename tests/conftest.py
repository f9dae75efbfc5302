"""Suite-wide fixtures. ``db_url``: every database test runs on SQLite and, when
``SOAKCAL_TEST_DATABASE_URL`` is set, on PostgreSQL too (skipped otherwise).

On PostgreSQL each test gets its own freshly created schema, selected with the
connection option ``search_path``, so tests never see each other's rows and
the schema is dropped afterwards. The names are random, so the worker processes of
``make test`` (pytest-xdist) and concurrent runs share the one database safely
(tests/pg_schemas.py). The URL returned is empty of tables: call
``service.db.session.upgrade_database(db_url)`` (or use ``migrated_db_url``).
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
from pg_schemas import new_schema_name, postgres_schema

# starlette's TestClient warns about httpx at import; not ours to fix, and noise in every run.
warnings.filterwarnings("ignore", message=".*httpx.*starlette.testclient.*")
warnings.filterwarnings("ignore", message=".*starlette.testclient.*httpx.*")

POSTGRES_ENV = "SOAKCAL_TEST_DATABASE_URL"

# One BLAS thread per process, set before anything imports numpy: `make test` runs one
# worker per core (pytest-xdist), and OpenBLAS' own threads on top of that spin against
# each other; on a busy 2-core machine a least-squares solve took 10x longer with 2
# threads than with 1. Exported, so the subprocesses the tests start inherit it.
for _blas in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_blas, "1")

# The suite never touches the real configuration home or a developer's database: every
# process it starts (and every subcommand it runs in-process) sees a throw-away home.
os.environ["SOAKCAL_HOME"] = tempfile.mkdtemp(prefix="soakcal-test-home-")
atexit.register(shutil.rmtree, os.environ["SOAKCAL_HOME"], True)
for _name in ("SOAKCAL_DATABASE_URL", "SOAKCAL_DATA_DIR"):
    os.environ.pop(_name, None)


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request: pytest.FixtureRequest, tmp_path) -> Iterator[str]:  # type: ignore[no-untyped-def]
    """An empty database: a temp SQLite file, or a fresh schema on the test PostgreSQL."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'soakcal-test.db'}"
        return
    base = os.environ.get(POSTGRES_ENV)
    if not base:
        pytest.skip(f"{POSTGRES_ENV} not set")
    yield from _postgres_schema(base)


@pytest.fixture
def migrated_db_url(db_url: str, request: pytest.FixtureRequest) -> str:
    """``db_url`` with the schema at Alembic head.

    On SQLite, a copy of a file migrated once per session (``_migrated_sqlite_file``): the
    same bytes the migrations write, without running them for every engine test (~0.35 s
    wall and 0.15 s CPU each, a migration per test of ~180). PostgreSQL migrates each
    schema: a schema cannot be copied.
    """
    from service.db.session import upgrade_database

    if db_url.startswith(SQLITE_PREFIX):
        template: Path = request.getfixturevalue("_migrated_sqlite_file")
        shutil.copyfile(template, db_url.removeprefix(SQLITE_PREFIX))
        return db_url
    upgrade_database(db_url)
    return db_url


SQLITE_PREFIX = "sqlite:///"


@pytest.fixture(scope="session")
def _migrated_sqlite_file(tmp_path_factory) -> Path:  # type: ignore[no-untyped-def]
    """A SQLite file at Alembic head, for ``migrated_db_url`` to copy. The engine is
    disposed after migrating, so the write-ahead log is folded into the file (checked:
    a copy of the file alone would otherwise miss what the log held)."""
    from service.db.session import upgrade_database

    path = tmp_path_factory.mktemp("migrated") / "soakcal-head.db"
    upgrade_database(f"{SQLITE_PREFIX}{path}")
    assert not path.with_name(path.name + "-wal").exists(), "migrations left a WAL behind"
    return path


@pytest.fixture(scope="session", params=["sqlite", "postgresql"])
def shared_db_url(request: pytest.FixtureRequest, tmp_path_factory) -> Iterator[str]:  # type: ignore[no-untyped-def]
    """One migrated database per backend for the whole session (see ``clean_db_url``)."""
    from service.db.session import upgrade_database

    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path_factory.mktemp('shared') / 'soakcal-shared.db'}"
        upgrade_database(url)
        yield url
        return
    base = os.environ.get(POSTGRES_ENV)
    if not base:
        pytest.skip(f"{POSTGRES_ENV} not set")
    for url in _postgres_schema(base):
        upgrade_database(url)
        yield url


@pytest.fixture
def clean_db_url(shared_db_url: str) -> str:
    """The shared migrated database, emptied: much faster than migrating per test.

    For tests of behaviour on a migrated schema; tests of the schema itself
    (migrations) use ``db_url``, which is fresh and empty.
    """
    from sqlalchemy import text

    from service.db.models import Base
    from service.db.session import make_engine

    engine = make_engine(shared_db_url)
    tables = [t.name for t in reversed(Base.metadata.sorted_tables)]
    try:
        with engine.begin() as conn:
            # DELETE + sequence restart: 3-4x faster than TRUNCATE on these tiny tables.
            for name in tables:
                conn.execute(text(f'DELETE FROM "{name}"'))
            if conn.dialect.name == "postgresql":
                sequences = conn.execute(
                    text(
                        "SELECT sequence_name FROM information_schema.sequences "
                        "WHERE sequence_schema = current_schema()"
                    )
                ).scalars()
                for sequence in list(sequences):
                    conn.execute(text(f'ALTER SEQUENCE "{sequence}" RESTART'))
    finally:
        engine.dispose()
    return shared_db_url


def _postgres_schema(base_url: str) -> Iterator[str]:
    yield from postgres_schema(base_url, new_schema_name())
