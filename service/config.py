"""Service settings: one place for the data directory, the database URL and runtime switches."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

DATA_DIR_ENV = "SOAKCAL_DATA_DIR"
DATABASE_URL_ENV = "SOAKCAL_DATABASE_URL"
RIGS_FILE_ENV = "SOAKCAL_RIGS_FILE"
DEFAULT_DATA_DIR = Path("soakcal-data")  # relative to the cwd, like the CLI's other outputs
SQLITE_FILENAME = "soakcal.db"


def data_dir() -> Path:
    """The directory for the embedded database (``SOAKCAL_DATA_DIR``, else ``./soakcal-data``)."""
    return Path(os.environ.get(DATA_DIR_ENV) or DEFAULT_DATA_DIR)


def default_sqlite_url() -> str:
    """The embedded SQLite file; its directory is created on demand by ``make_engine``."""
    return f"sqlite:///{(data_dir() / SQLITE_FILENAME).resolve()}"


def resolve_database_url(explicit: str | None = None) -> str:
    """An explicit URL, else ``SOAKCAL_DATABASE_URL``, else the embedded SQLite file."""
    return explicit or os.environ.get(DATABASE_URL_ENV) or default_sqlite_url()


def service_version() -> str:
    """The installed package version (what ``/api/v1/health`` reports)."""
    try:
        from importlib.metadata import version

        return version("soakcal")
    except Exception:  # not installed (running from a source tree)
        return "0.0.0+unknown"


@dataclass
class Settings:
    """What ``create_app`` needs. Defaults suit ``soakcal serve``; tests switch parts off."""

    database_url: str = field(default_factory=resolve_database_url)
    sim_speed: float = 600.0
    # The campaign runner manager (service.engine.manager); API tests fake its state writes.
    run_engine: bool = True
    run_scheduler: bool = True
    scheduler_interval_s: float = 5.0
    # Bring the schema to head at start (``soakcal serve`` also does it before uvicorn).
    migrate: bool = True
    seed_sim_rig: bool = True
    # A JSON list of rig configs registered (or updated while idle) at start.
    rigs_file: str | None = field(default_factory=lambda: os.environ.get(RIGS_FILE_ENV) or None)
    # How often /events re-reads the campaign row (the runner may be another process).
    events_poll_s: float = 0.5
    # A comment line keeps proxies from closing an idle SSE stream.
    events_heartbeat_s: float = 15.0
    engine_owner: str | None = None
    # The rigs this process's campaign engine drives (``serve --rigs``, SOAKCAL_ENGINE_RIGS):
    # None every rig, an empty set none (API only). service/engine/worker.py parses it.
    engine_rigs: frozenset[str] | None = field(default_factory=lambda: _engine_rigs())


def _engine_rigs() -> frozenset[str] | None:
    from service.engine.worker import engine_rigs_from_env

    return engine_rigs_from_env()
