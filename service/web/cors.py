"""CORS for an external dashboard: origins from ``SOAKCAL_CORS_ORIGINS``, off by default.

Credentials (cookies) are never allowed cross-origin: another site's page
must present a bearer token, so the dashboard's sign-in cookie cannot be
ridden from it.
"""

from __future__ import annotations

import os

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware

CORS_ORIGINS_ENV = "SOAKCAL_CORS_ORIGINS"


def cors_origins(raw: str | None = None) -> list[str]:
    """Comma-separated origins (``https://lab.example:8443``) or ``*``; empty means off."""
    text = os.environ.get(CORS_ORIGINS_ENV, "") if raw is None else raw
    origins = [o.strip().rstrip("/") for o in text.split(",") if o.strip()]
    for origin in origins:
        if origin != "*" and not origin.startswith(("http://", "https://")):
            raise ValueError(
                f"{CORS_ORIGINS_ENV}: {origin!r} is not an origin (expected http(s)://host[:port])"
            )
    return origins


def add_cors(app: FastAPI, raw: str | None = None) -> None:
    """Answer preflights and add CORS headers for the configured origins (nothing if none)."""
    origins = cors_origins(raw)
    if not origins:
        return
    app.add_middleware(
        CORSMiddleware,
        allow_origins=origins,
        allow_credentials=False,
        allow_methods=["GET", "POST", "DELETE"],
        allow_headers=["Authorization", "Content-Type"],
        max_age=600,
    )
