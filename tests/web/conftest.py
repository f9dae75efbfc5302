"""A live service with the campaign engine on the ``sim`` rig, for the browser test."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import uvicorn
from web_helpers import LiveService, chromium_or_skip


@pytest.fixture
def live_engine_service(tmp_path: Path) -> Iterator[LiveService]:
    """uvicorn in a thread on a free port, the engine running the sim rig fast."""
    chromium_or_skip()  # before starting anything
    from service.api.app import create_app
    from service.api.auth import create_token
    from service.config import Settings
    from service.db.session import session_scope

    settings = Settings(
        database_url=f"sqlite:///{tmp_path / 'browser.db'}",
        run_engine=True,
        run_scheduler=False,
        # fast enough to finish in seconds, slow enough that a pause lands mid-campaign
        sim_speed=1200.0,
        events_poll_s=0.1,
    )
    app = create_app(settings)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.02)
    assert server.started, "the service did not start within 20 s"
    tokens = {}
    with session_scope(app.state.session_factory) as session:
        for role in ("viewer", "operator"):
            tokens[role] = create_token(session, role, f"browser {role}")
    yield LiveService(url=f"http://127.0.0.1:{port}", tokens=tokens)
    server.should_exit = True
    thread.join(timeout=20)
