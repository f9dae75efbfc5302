"""Health: no auth; 503 with database "error" when the database does not answer."""

from __future__ import annotations

from fastapi.testclient import TestClient

from service.db.session import make_session_factory


def test_health_needs_no_token(client: TestClient) -> None:
    response = client.get("/api/v1/health")
    assert response.status_code == 200
    body = response.json()
    assert body["status"] == "ok" and body["database"] == "ok" and body["version"]


def test_health_is_503_when_the_database_is_gone(client: TestClient) -> None:
    app = client.app
    working = app.state.session_factory  # type: ignore[attr-defined]
    # Nothing listens on port 1: the connection is refused at once.
    app.state.session_factory = make_session_factory(  # type: ignore[attr-defined]
        "postgresql+psycopg://nobody@127.0.0.1:1/none?connect_timeout=2"
    )
    try:
        response = client.get("/api/v1/health")
    finally:
        app.state.session_factory = working  # type: ignore[attr-defined]
    assert response.status_code == 503
    assert response.json()["database"] == "error" and response.json()["status"] == "error"
