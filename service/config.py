"""Service settings: one configuration home, the database URL and runtime switches.

Every subcommand (``serve``, ``token create``, ``campaign plan`` …) finds the
same database whatever the current folder:

1. ``SOAKCAL_DATABASE_URL`` when set (PostgreSQL in production);
2. else the SQLite file ``soakcal.db`` in the configuration home:
   ``SOAKCAL_HOME``, else the legacy ``SOAKCAL_DATA_DIR`` (container images),
   else the per-user data directory (``$XDG_DATA_HOME/soakcal``, default
   ``~/.local/share/soakcal``; ``%LOCALAPPDATA%\\soakcal`` on Windows).

:func:`database_choice` says which rule chose the URL, so commands can print it;
:func:`check_database_url` names the part of a bad URL that is wrong.
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

HOME_ENV = "SOAKCAL_HOME"
DATA_DIR_ENV = "SOAKCAL_DATA_DIR"  # legacy name of SOAKCAL_HOME (kept for container images)
DATABASE_URL_ENV = "SOAKCAL_DATABASE_URL"
RIGS_FILE_ENV = "SOAKCAL_RIGS_FILE"
ENGINE_RIGS_ENV = "SOAKCAL_ENGINE_RIGS"  # the rigs this process drives (``serve --rigs``)
_RIG_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
MAX_BODY_BYTES_ENV = "SOAKCAL_MAX_BODY_BYTES"
DEFAULT_MAX_BODY_BYTES = 1_000_000
SQLITE_FILENAME = "soakcal.db"
SUPPORTED_BACKENDS = ("sqlite", "postgresql")


class ConfigError(ValueError):
    """A setting that cannot work; the message is one line naming the setting and the part."""


def user_data_dir() -> Path:
    """The per-user data directory for soakcal (XDG on POSIX, LOCALAPPDATA on Windows)."""
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "soakcal"
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "soakcal"


def home_dir() -> Path:
    """The configuration home (``SOAKCAL_HOME`` > ``SOAKCAL_DATA_DIR`` > per-user), absolute."""
    chosen = os.environ.get(HOME_ENV) or os.environ.get(DATA_DIR_ENV)
    return (Path(chosen).expanduser() if chosen else user_data_dir()).resolve()


def data_dir() -> Path:
    """Where the embedded database lives: the configuration home."""
    return home_dir()


def default_sqlite_url() -> str:
    """The embedded SQLite file; its directory is created on demand by ``make_engine``."""
    return f"sqlite:///{data_dir() / SQLITE_FILENAME}"


def resolve_database_url(explicit: str | None = None) -> str:
    """An explicit URL, else ``SOAKCAL_DATABASE_URL``, else the SQLite file in the home."""
    return explicit or os.environ.get(DATABASE_URL_ENV) or default_sqlite_url()


def database_choice() -> tuple[str, str]:
    """``(url, why)``: the URL every subcommand uses and which rule picked it."""
    if os.environ.get(DATABASE_URL_ENV):
        return os.environ[DATABASE_URL_ENV], f"from {DATABASE_URL_ENV}"
    if os.environ.get(HOME_ENV):
        return default_sqlite_url(), f"in {HOME_ENV}"
    if os.environ.get(DATA_DIR_ENV):
        return default_sqlite_url(), f"in {DATA_DIR_ENV}"
    return default_sqlite_url(), f"in the per-user home (set {HOME_ENV} to move it)"


def check_database_url(url: str, source: str = DATABASE_URL_ENV) -> str:
    """``url`` when SQLAlchemy can use it; else :class:`ConfigError` naming the wrong part."""
    from sqlalchemy import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    example = "e.g. postgresql+psycopg://user@host:5432/soakcal or sqlite:////path/soakcal.db"
    if "://" not in url:
        raise ConfigError(f"{source}: {url[:60]!r} is not a URL (no '://'); {example}")
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError) as exc:
        raise ConfigError(f"{source}: cannot parse the URL ({_first_line(exc)}); "
                          f"{example}") from None
    backend = parsed.get_backend_name()
    if backend not in SUPPORTED_BACKENDS:
        raise ConfigError(f"{source}: scheme {parsed.drivername!r}: database {backend!r} is not "
                          f"supported (expected {' or '.join(SUPPORTED_BACKENDS)}); {example}")
    try:
        parsed.get_dialect()
    except NoSuchModuleError:
        raise ConfigError(f"{source}: scheme {parsed.drivername!r}: no driver "
                          f"{parsed.get_driver_name()!r} for {backend} (use "
                          f"{'sqlite' if backend == 'sqlite' else 'postgresql+psycopg'})"
                          ) from None
    if parsed.port is not None and not 0 < parsed.port < 65536:
        raise ConfigError(f"{source}: port {parsed.port} is out of range 1..65535")
    if backend == "postgresql" and not parsed.database:
        raise ConfigError(f"{source}: no database name after the host (…/soakcal)")
    if backend == "sqlite" and not parsed.database:
        raise ConfigError(f"{source}: no file path (sqlite:////absolute/path/soakcal.db)")
    return url


def max_body_bytes() -> int:
    """``SOAKCAL_MAX_BODY_BYTES`` (a positive integer), default 1 MB."""
    raw = os.environ.get(MAX_BODY_BYTES_ENV)
    if not raw:
        return DEFAULT_MAX_BODY_BYTES
    if not raw.strip().isdigit() or int(raw) < 1:
        raise ConfigError(f"{MAX_BODY_BYTES_ENV}: expected a positive number of bytes, "
                          f"got {raw[:40]!r}")
    return int(raw)


def _first_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]


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
    # Request bodies over this are refused with 413 before they are parsed.
    max_body_bytes: int = field(default_factory=max_body_bytes)
    # The rigs this process's campaign engine drives (``serve --rigs``, SOAKCAL_ENGINE_RIGS):
    # None every rig, an empty set none (API only).
    engine_rigs: frozenset[str] | None = field(
        default_factory=lambda: parse_rigs(os.environ.get(ENGINE_RIGS_ENV)))


def parse_rigs(text: str | None) -> frozenset[str] | None:
    """``"lab-1,lab-2"`` → those rigs; ``"none"`` → no rig (API only); empty/None → every rig.

    Raises ``ValueError`` naming the bad entry.
    """
    if text is None or not text.strip():
        return None
    if text.strip().lower() == "none":
        return frozenset()
    names = [n.strip() for n in text.split(",")]
    for i, name in enumerate(names):
        if not _RIG_NAME.match(name):
            raise ValueError(f"--rigs entry {i + 1} {name!r} is not a rig name "
                             "(letters, digits, '-', '_', '.'; or 'none')")
    return frozenset(names)
