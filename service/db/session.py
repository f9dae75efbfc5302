"""Engines, sessions and schema migrations for SQLite (embedded) and PostgreSQL.

Several processes share one database (``soakcal serve``, ``soakcal token
create``, a second service instance), so SQLite connections get WAL mode
(readers never block the writer), enforced foreign keys and a busy timeout
(a writer waits for the lock instead of failing at once).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import Engine, create_engine, event, make_url
from sqlalchemy.orm import Session, sessionmaker

from service.config import resolve_database_url

SQLITE_BUSY_TIMEOUT_MS = 10_000
MIGRATIONS_DIR = Path(__file__).resolve().parent.parent / "migrations"


# Sync FastAPI handlers run on a 40-thread pool and validate their response on it while
# their session still holds a connection. With fewer connections than threads, a burst
# of 40+ requests can leave every thread waiting for a connection held by a request
# that waits for a thread (seen by benchmarks/bench_query_latency.py with 15: 500s
# after the 30 s pool timeout). 45 > 40 removes the common case; two service processes
# stay under PostgreSQL's default max_connections of 100.
POOL_SIZE, POOL_MAX_OVERFLOW = 10, 35


def make_engine(url: str | None = None) -> Engine:
    """An engine for ``url`` (resolved like the service does when None)."""
    url = resolve_database_url(url)
    parsed = make_url(url)
    pool = {"pool_size": POOL_SIZE, "max_overflow": POOL_MAX_OVERFLOW}
    if parsed.get_backend_name() != "sqlite":
        # pre_ping: a PostgreSQL restart should cost one retry, not a 500.
        return create_engine(url, pool_pre_ping=True, **pool)
    if parsed.database and parsed.database != ":memory:":
        Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
    else:
        pool = {}  # in-memory SQLite uses a single-connection pool
    engine = create_engine(url, connect_args={"timeout": SQLITE_BUSY_TIMEOUT_MS / 1000}, **pool)
    event.listen(engine, "connect", _sqlite_pragmas)
    return engine


def _sqlite_pragmas(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
    cursor.close()


def make_session_factory(engine_or_url: Engine | str | None = None) -> sessionmaker[Session]:
    """A ``sessionmaker`` bound to an engine (or to a new engine for a URL).

    ``expire_on_commit=False`` so objects can be serialised after the commit that
    created them without another round trip.
    """
    engine = engine_or_url if isinstance(engine_or_url, Engine) else make_engine(engine_or_url)
    return sessionmaker(bind=engine, expire_on_commit=False)


@contextmanager
def session_scope(factory: sessionmaker[Session]) -> Iterator[Session]:
    """A session that commits on success and rolls back on error."""
    with factory() as session:
        try:
            yield session
            session.commit()
        except BaseException:
            session.rollback()
            raise


def alembic_config(url: str | None = None):  # type: ignore[no-untyped-def]
    """An Alembic ``Config`` whose scripts live inside the package (works from any cwd)."""
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    if url is not None:
        # ConfigParser interpolates '%': escape it (URL-encoded passwords, search_path options).
        cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def upgrade_database(url: str | None = None, revision: str = "head") -> None:
    """Run the Alembic migrations up to ``revision`` on the database at ``url``.

    The connection comes from :func:`make_engine` so SQLite gets the same pragmas
    as the service; concurrent starts are safe on PostgreSQL (transactional DDL)
    and serialised by the file lock on SQLite.
    """
    _migrate(url, "upgrade", revision)


def downgrade_database(url: str | None, revision: str) -> None:
    """Undo the migrations above ``revision`` (``"base"``: all of them) on the database at
    ``url``, as :func:`upgrade_database` runs them: rolling a release back, and the
    migrations' own tests (each downgrade must undo its upgrade)."""
    _migrate(url, "downgrade", revision)


def _migrate(url: str | None, direction: str, revision: str) -> None:
    """Alembic's ``upgrade`` or ``downgrade`` to ``revision`` in one transaction."""
    from sqlalchemy.exc import InterfaceError, OperationalError

    from alembic import command

    engine = make_engine(url)
    try:
        with engine.begin() as connection:
            cfg = alembic_config()
            cfg.attributes["connection"] = connection
            getattr(command, direction)(cfg, revision)
    except (OperationalError, InterfaceError) as exc:
        raise DatabaseUnavailable(engine.url, exc) from exc
    finally:
        engine.dispose()


class DatabaseUnavailable(RuntimeError):
    """The database cannot be opened: one line with the URL (no password) and the reason."""

    def __init__(self, url: object, exc: BaseException) -> None:
        from sqlalchemy import URL

        shown = url.render_as_string(hide_password=True) if isinstance(url, URL) else str(url)
        reason = str(getattr(exc, "orig", None) or exc).strip().splitlines() or ["unknown"]
        super().__init__(f"cannot open the database {shown}: {reason[0][:200]}")
