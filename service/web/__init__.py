"""The lab's browser: the dashboard at ``/``, offline API docs, sign-in cookie, CORS.

Registered by ``service.api.app.create_app`` with ``include_router(web.router)``,
``mount_static(app)`` and ``add_cors(app)``; see docs/web.md.
"""

from __future__ import annotations

from fastapi import APIRouter

from service.web import calibration_page, docs, figures, history, pages, session
from service.web.cors import add_cors
from service.web.pages import mount_static

router = APIRouter()
for _module in (pages, docs, session, figures, history, calibration_page):
    router.include_router(_module.router)

__all__ = ["add_cors", "mount_static", "router"]
