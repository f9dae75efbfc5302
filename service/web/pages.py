"""The dashboard page at ``/`` and its static assets under ``/static`` (all from the package)."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

from service.web.docs import DOCS_ASSETS_DIR, DOCS_ASSETS_URL

STATIC_DIR = Path(__file__).parent / "static"
STATIC_URL = "/static"
# Everything from this origin, nothing inline: a CDN reference or an injected script
# would be refused by the browser, which is also how the browser test proves "offline".
CSP = (
    "default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'"
)

router = APIRouter(include_in_schema=False)


@router.get("/")
async def dashboard() -> FileResponse:
    return FileResponse(
        STATIC_DIR / "index.html",
        media_type="text/html; charset=utf-8",
        headers={
            "Content-Security-Policy": CSP,
            "X-Content-Type-Options": "nosniff",
            "Cache-Control": "no-cache",
        },
    )


def mount_static(app: FastAPI) -> None:
    """Serve the dashboard's files and the API docs' bundles."""
    app.mount(STATIC_URL, StaticFiles(directory=STATIC_DIR), name="static")
    app.mount(DOCS_ASSETS_URL, StaticFiles(directory=DOCS_ASSETS_DIR), name="docs-assets")
