"""The lab's browser, server side: offline docs, the dashboard page, cookie sign-in, CSRF, CORS."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from service.api.app import create_app
from service.api.auth import CSRF_HEADER, SESSION_COOKIE
from service.config import Settings
from service.web.cors import cors_origins

CSRF = {CSRF_HEADER: "1"}


def _token(auth, role: str) -> str:  # type: ignore[no-untyped-def]
    return auth[role]["Authorization"].removeprefix("Bearer ")


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_api_docs_reference_only_assets_the_service_serves(client: TestClient, page: str) -> None:
    html = client.get(page)
    assert html.status_code == 200
    assert "default-src 'self'" in html.headers["content-security-policy"]
    urls = re.findall(r'(?:src|href)="([^"]+)"|url: *[\'"]([^\'"]+)[\'"]', html.text)
    urls = [a or b for a, b in urls]
    assert urls, html.text[:300]
    for url in urls:
        assert url.startswith("/"), f"{page} loads {url} from elsewhere"
        assert client.get(url).status_code == 200, url
    assert "cdn" not in html.text.lower()


def test_the_dashboard_and_its_assets_come_from_the_service(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200
    assert page.headers["content-type"].startswith("text/html")
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assets = re.findall(r'(?:src|href)="(/[^"]+)"', page.text)
    assert "/static/app.js" in assets and "/static/app.css" in assets
    for url in assets:
        assert client.get(url).status_code == 200, url
    assert not re.search(r'(?:src|href)="(?:https?:)?//', page.text)


def test_sign_in_sets_an_httponly_strict_cookie(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    response = client.post("/web/session", json={"token": _token(auth, "operator")}, headers=CSRF)
    assert response.status_code == 200
    assert response.json()["role"] == "operator"
    cookie = response.headers["set-cookie"]
    assert cookie.startswith(f"{SESSION_COOKIE}=")
    assert "HttpOnly" in cookie and "SameSite=strict" in cookie and "Path=/" in cookie
    assert client.get("/web/session").json()["role"] == "operator"
    assert client.get("/api/v1/campaigns").status_code == 200  # cookie, no bearer


def test_sign_in_with_a_bad_token_or_without_the_header(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.post("/web/session", json={"token": "sct_nope"}, headers=CSRF).status_code == 401
    assert SESSION_COOKIE not in client.cookies
    plain = client.post("/web/session", json={"token": _token(auth, "viewer")})
    assert plain.status_code == 403
    assert client.get("/web/session").status_code == 401


def test_a_cookie_change_needs_the_csrf_header_and_origin(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    client.post("/web/session", json={"token": _token(auth, "operator")}, headers=CSRF)
    body = {"rig": "sim", "sensor": "SN-WEB-1", "setpoints_c": [20.0]}
    refused = client.post("/api/v1/campaigns", json=body)
    assert refused.status_code == 403 and CSRF_HEADER in refused.json()["detail"]
    foreign = {**CSRF, "Origin": "http://evil.example"}
    assert client.post("/api/v1/campaigns", json=body, headers=foreign).status_code == 403
    same = {**CSRF, "Origin": "http://testserver"}
    assert client.post("/api/v1/campaigns", json=body, headers=same).status_code == 201
    # bearer clients (curl, the CLI) need no such header
    client.cookies.clear()
    assert client.post("/api/v1/campaigns", json=body, headers=auth["operator"]).status_code == 201


def test_revoking_the_token_signs_the_browser_out(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    created = client.post("/api/v1/tokens", json={"role": "viewer"}, headers=auth["admin"]).json()
    client.post("/web/session", json={"token": created["token"]}, headers=CSRF)
    assert client.get("/web/session").status_code == 200
    client.delete(f"/api/v1/tokens/{created['id']}", headers=auth["admin"])
    assert client.get("/web/session").status_code == 401


def test_sign_out_clears_the_cookie(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    client.post("/web/session", json={"token": _token(auth, "viewer")}, headers=CSRF)
    assert client.delete("/web/session", headers=CSRF).status_code == 204
    assert client.get("/web/session").status_code == 401


def test_cors_is_off_by_default(client: TestClient) -> None:
    pre = client.options(
        "/api/v1/rigs",
        headers={"Origin": "http://dash.lab", "Access-Control-Request-Method": "GET"},
    )
    assert "access-control-allow-origin" not in pre.headers


def test_cors_origins_from_the_environment(settings: Settings, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setenv("SOAKCAL_CORS_ORIGINS", "http://dash.lab:8080, https://ops.lab")
    with TestClient(create_app(settings)) as client:
        pre = client.options(
            "/api/v1/rigs",
            headers={"Origin": "http://dash.lab:8080", "Access-Control-Request-Method": "GET",
                     "Access-Control-Request-Headers": "authorization"},
        )
        assert pre.status_code == 200
        assert pre.headers["access-control-allow-origin"] == "http://dash.lab:8080"
        assert "access-control-allow-credentials" not in pre.headers
        other = client.get("/api/v1/health", headers={"Origin": "http://elsewhere"})
        assert "access-control-allow-origin" not in other.headers


def test_a_malformed_cors_origin_is_one_clear_error() -> None:
    with pytest.raises(ValueError, match="SOAKCAL_CORS_ORIGINS: 'dash.lab' is not an origin"):
        cors_origins("dash.lab")
    assert cors_origins("") == []


def test_a_signed_in_viewer_reads_but_cannot_control(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    body = {"rig": "sim", "sensor": "SN-WEB-2", "setpoints_c": [20.0]}
    campaign = client.post("/api/v1/campaigns", json=body, headers=auth["operator"]).json()
    client.post("/web/session", json={"token": _token(auth, "viewer")}, headers=CSRF)
    assert client.get(f"/api/v1/campaigns/{campaign['id']}").status_code == 200
    pause = client.post(f"/api/v1/campaigns/{campaign['id']}/pause", headers=CSRF)
    assert pause.status_code == 403 and "operator" in pause.json()["detail"]


def test_figures_of_an_unknown_calibration_are_404(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    assert client.get("/web/calibrations/5/figures").status_code == 401
    response = client.get("/web/calibrations/5/figures", headers=auth["viewer"])
    assert response.status_code == 404 and "not found" in response.json()["detail"]
    viewer = auth["viewer"]
    assert client.get("/web/calibrations/5/figures/x.png", headers=viewer).status_code == 404
    assert client.get(f"/web/calibrations/{2**40}/figures", headers=viewer).status_code == 422
