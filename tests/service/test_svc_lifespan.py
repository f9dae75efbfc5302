"""The app lifespan: migrations at start, the sim rig, and the engine started and stopped."""

from __future__ import annotations

import sys
import types

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import inspect

from service.api.app import create_app
from service.config import Settings
from service.db.session import make_engine


class FakeManager:
    instances: list[FakeManager] = []

    def __init__(self, session_factory, *, sim_speed: float, clock_factory=None, owner=None):  # type: ignore[no-untyped-def]
        self.session_factory, self.sim_speed, self.owner = session_factory, sim_speed, owner
        self.events: list[str] = []
        FakeManager.instances.append(self)

    async def start(self) -> None:
        self.events.append("start")

    async def stop(self) -> None:
        self.events.append("stop")


def test_start_migrates_an_empty_database_and_runs_the_engine(
    db_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    fake = types.ModuleType("service.engine.manager")
    fake.CampaignManager = FakeManager  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "service.engine.manager", fake)
    FakeManager.instances.clear()
    settings = Settings(database_url=db_url, sim_speed=1200.0, run_scheduler=False)
    with TestClient(create_app(settings)) as client:
        assert client.get("/api/v1/health").json()["database"] == "ok"
        [manager] = FakeManager.instances
        assert manager.events == ["start"] and manager.sim_speed == 1200.0
        assert manager.session_factory is client.app.state.session_factory  # type: ignore[attr-defined]
    assert manager.events == ["start", "stop"]
    engine = make_engine(db_url)
    try:
        with engine.connect() as conn:
            assert "campaigns" in inspect(conn).get_table_names()
    finally:
        engine.dispose()


def test_scheduler_runs_in_the_lifespan(clean_db_url: str) -> None:
    settings = Settings(
        database_url=clean_db_url, run_engine=False, migrate=False, scheduler_interval_s=0.01
    )
    with TestClient(create_app(settings)) as client:
        [scheduler] = client.app.state.background  # type: ignore[attr-defined]
        assert type(scheduler).__name__ == "Scheduler"
