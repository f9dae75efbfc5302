"""Helpers for the service tests (imported by name: pytest puts this directory on sys.path)."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient
from sqlalchemy.orm import Session, sessionmaker

from service.db.models import Campaign
from service.db.session import session_scope


def set_campaign(sf: sessionmaker[Session], campaign_id: int, **values: Any) -> None:
    """Write campaign columns as the runner (another process) would."""
    with session_scope(sf) as session:
        campaign = session.get(Campaign, campaign_id)
        assert campaign is not None
        for key, value in values.items():
            setattr(campaign, key, value)


def new_campaign(client: TestClient, headers: dict[str, str], **body: Any) -> dict[str, Any]:
    response = client.post(
        "/api/v1/campaigns", json={"rig": "sim", "sensor": "SN-0001", **body}, headers=headers
    )
    assert response.status_code == 201, response.text
    return response.json()
