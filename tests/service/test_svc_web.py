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


def _stored_campaign(sf, serials: list[str]) -> int:  # type: ignore[no-untyped-def]
    """A campaign with two measurements per sensor and a soak probe, as a runner stores them."""
    from service.db.models import Campaign, Measurement, SoakProbe
    from service.db.session import session_scope

    spec = {"setpoints_c": [20.0, 40.0], **({"sensors": serials} if len(serials) > 1 else {})}
    with session_scope(sf) as session:
        c = Campaign(rig="sim", sensor=serials[0], spec=spec, state="completed",
                     steps_log=[{"step": 0, "setpoint_c": 20.0, "soak_start_t_s": 5.0,
                                 "soak_end_t_s": 9.0, "reason": "stable", "soak_s": 4.0}])
        session.add(c)
        session.flush()
        for i, serial in enumerate(serials):
            for t_s, chamber_c in ((10.0, 20.1), (30.0, 39.8)):
                session.add(Measurement(
                    campaign_id=c.id, sensor=serial, step=int(t_s > 20), position=0, t_s=t_s,
                    setpoint_c=20.0 if t_s < 20 else 40.0, chamber_c=chamber_c,
                    sensor_c=chamber_c + 1 + i, ref_x=0, ref_y=0, ref_z=1, ax=0, ay=0, az=1, n=10))
            session.add(SoakProbe(campaign_id=c.id, sensor=serial, step=0, soak_start_t_s=5.0,
                                  pose="z", t_s=7.0, setpoint_c=20.0, chamber_c=20.3,
                                  sensor_c=22.0 + i, ax=0, ay=0, az=1, n=10))
        return int(c.id)


def test_the_temperature_history_is_read_from_what_is_stored(client: TestClient, sf, auth) -> None:  # type: ignore[no-untyped-def]
    cid = _stored_campaign(sf, ["SN-H1", "SN-H2"])
    path = f"/web/campaigns/{cid}/temperatures"
    assert client.get(path).status_code == 401
    body = client.get(path, headers=auth["viewer"]).json()
    # time order, measurements and probes together; the chamber read once (first sensor)
    assert body["chamber_c"] == [[7.0, 20.3], [10.0, 20.1], [30.0, 39.8]]
    assert body["setpoint_c"] == [[7.0, 20.0], [10.0, 20.0], [30.0, 40.0]]
    assert body["die_c"] == {"SN-H1": [[7.0, 22.0], [10.0, 21.1], [30.0, 40.8]],
                             "SN-H2": [[7.0, 23.0], [10.0, 22.1], [30.0, 41.8]]}
    assert body["soaks"][0]["reason"] == "stable"
    missing = client.get("/web/campaigns/999/temperatures", headers=auth["viewer"])
    assert missing.status_code == 404 and "not found" in missing.json()["detail"]


def test_a_long_history_is_thinned_keeping_the_last_point() -> None:
    from service.web.history import thin

    points = [(float(t), 20.0 + t / 1000) for t in range(10_001)]
    kept = thin(points, limit=1000)
    assert len(kept) <= 1001 and kept[0] == points[0] and kept[-1] == points[-1]
    assert thin(points[:5], limit=1000) == points[:5]


def test_the_calibration_summary_reads_the_stored_report(client: TestClient, sf, auth) -> None:  # type: ignore[no-untyped-def]
    from service.db.models import Calibration
    from service.db.session import session_scope

    cid = _stored_campaign(sf, ["SN-S1"])
    report = {
        "mode": "norm", "method": "joint", "degree": 1, "temperature_source": "sensor_c",
        "identifiable": {"bx": True, "sx": True, "ayx": False},
        "joint_fit": {"success": True, "chi2_red": 1.1},
        "drift": {"before": {"abs_slope_ug_per_k": 90.0}, "after": {"abs_slope_ug_per_k": 0.2}},
        "notes": ["polynomial degree reduced from 3 to 1"],
        "steps": [{"step": 0, "setpoint_c": 20.0, "temperature_c": 21.0, "positions": 6,
                   "rmse_before_mg": 3.0, "rmse_measurement_mg": 0.02,
                   "rmse_polynomial_mg": 0.03, "chi2_red": 1.2},
                  {"step": 1, "setpoint_c": 40.0, "temperature_c": 41.0, "positions": 6,
                   "rmse_before_mg": 4.0, "rmse_measurement_mg": 0.02,
                   "rmse_polynomial_mg": 0.04, "chi2_red": 0.9}]}
    with session_scope(sf) as session:
        row = Calibration(sensor="SN-S1", campaign_id=cid, valid_lo_c=20.0, valid_hi_c=41.0,
                          rmse_ug=35.4, model_version="sfem-cubic-1",
                          model={"provenance": {"degree_requested": 3}}, report=report,
                          provenance={"steps_log": [{"step": 0, "soak_s": 4.0,
                                                     "reason": "stable"}]})
        session.add(row)
        session.flush()
        cal_id = row.id
    body = client.get(f"/web/calibrations/{cal_id}/summary", headers=auth["viewer"]).json()
    assert body["rmse_before_ug"] == 3535.5  # rms of 3000 and 4000 µg
    assert body["rmse_after_ug"] == 35.4 and body["valid_c"] == [20.0, 41.0]
    assert body["fitted"] == ["bx", "sx"] and body["held"] == ["ayx"]
    assert (body["degree"], body["degree_requested"]) == (1, 3)
    assert body["drift_ug_per_k"] == {"before": 90.0, "after": 0.2}
    first, second = body["steps"]
    assert (first["rmse_before_ug"], first["rmse_step_fit_ug"], first["rmse_after_ug"]) == (
        3000.0, 20.0, 30.0)
    assert (first["soak_s"], first["soak_reason"]) == (4.0, "stable")
    assert second["soak_reason"] is None
    missing = client.get("/web/calibrations/999/summary", headers=auth["viewer"])
    assert missing.status_code == 404


def _model_doc(bx_g: float, tempco_g_per_c: float, valid_c: tuple[float, float]) -> dict:  # type: ignore[type-arg]
    """A model document's thermal part: bx = bx_g + tempco·(T − 25), the rest nominal."""
    names = ("bx", "by", "bz", "sx", "sy", "sz", "ayx", "azx", "azy", "mx", "my", "mz")
    coefficients = {n: [1.0 if n.startswith("s") else 0.0, 0.0] for n in names}
    coefficients["bx"] = [bx_g, tempco_g_per_c]
    units = {n: (["1", "1/degC"] if n.startswith("s") else ["g", "g/degC"]) for n in names}
    return {"temperature": {"centre_c": 25.0, "valid_c": list(valid_c)},
            "polynomial": {"physical_coefficients": coefficients, "physical_units": units},
            "provenance": {"sensor_identity": {"reported_model": "ADXL355"}}}


def test_lot_statistics_flag_the_sensor_outside_four_sigma(client: TestClient, sf, auth) -> None:  # type: ignore[no-untyped-def]
    from service.db.models import Calibration
    from service.db.session import session_scope

    bx_mg = [1.0, 1.2, 0.9, 1.1, 1.05, 0.95, 9.0]  # the last one is off its lot
    ids = {}
    with session_scope(sf) as session:
        for i, bx in enumerate(bx_mg):
            # an older calibration of the same sensor does not count, only its latest
            for version, value in (("old", 50.0), ("new", bx)):
                row = Calibration(sensor=f"SN-LOT-{i}", valid_lo_c=0.0, valid_hi_c=50.0,
                                  rmse_ug=30.0, model_version=version,
                                  model=_model_doc(value * 1e-3, 2e-6, (0.0, 50.0)))
                session.add(row)
                session.flush()
                ids[i] = row.id
        session.add(Calibration(sensor="SN-LOT-COLD", valid_lo_c=-40.0, valid_hi_c=0.0,
                                rmse_ug=30.0, model_version="new",
                                model=_model_doc(1e-3, 2e-6, (-40.0, 0.0))))
    body = client.get("/api/v1/fleet/lots", headers=auth["viewer"]).json()
    (lot,) = body["lots"]
    assert lot["model"] == "ADXL355" and lot["sensors"] == 7
    assert lot["left_out"] == ["SN-LOT-COLD"]  # 25 °C is outside its valid range
    bx = next(s for s in lot["spreads"] if s["name"] == "bx")
    assert bx["median"] == pytest.approx(1.05e-3)
    assert bx["sigma"] == pytest.approx(1.4826 * 0.1e-3, rel=1e-6)
    assert [(f["sensor"], f["name"]) for f in lot["flags"]] == [("SN-LOT-6", "bx")]
    assert lot["flags"][0]["z"] == pytest.approx((9.0 - 1.05) / (1.4826 * 0.1), abs=0.1)
    tempco = next(s for s in lot["spreads"] if s["name"] == "dbx/dT")
    assert tempco["median"] == pytest.approx(2e-6) and tempco["unit"] == "g/degC"
    flagged = client.get(f"/api/v1/fleet/calibrations/{ids[6]}", headers=auth["viewer"]).json()
    assert [f["name"] for f in flagged["flags"]] == ["bx"] and flagged["sensors"] == 7
    within = client.get(f"/api/v1/fleet/calibrations/{ids[0]}", headers=auth["viewer"]).json()
    assert (within["model"], within["flags"], within["note"]) == ("ADXL355", [], None)
    older = client.get(f"/api/v1/fleet/calibrations/{ids[0] - 1}", headers=auth["viewer"]).json()
    assert older["model"] is None and older["note"].startswith("not compared: not its sensor")
    # at 45 °C the tempco moves every sensor alike: the same one stands out
    warm = client.get("/api/v1/fleet/lots?reference_c=45", headers=auth["viewer"]).json()
    assert [f["sensor"] for f in warm["lots"][0]["flags"]] == ["SN-LOT-6"]


def test_a_small_lot_flags_no_one_and_says_why(client: TestClient, sf, auth) -> None:  # type: ignore[no-untyped-def]
    from service.db.models import Calibration
    from service.db.session import session_scope

    with session_scope(sf) as session:
        for i, bx in enumerate((1.0, 1.1, 30.0)):
            session.add(Calibration(sensor=f"SN-FEW-{i}", valid_lo_c=0.0, valid_hi_c=50.0,
                                    rmse_ug=30.0, model_version="v",
                                    model=_model_doc(bx * 1e-3, 0.0, (0.0, 50.0))))
    (lot,) = client.get("/api/v1/fleet/lots", headers=auth["viewer"]).json()["lots"]
    assert lot["flags"] == []
    assert lot["note"] == "3 sensor(s) at 25 °C: at least 5 are needed to flag one"


def test_a_large_lot_plots_a_sample_and_every_flagged_sensor() -> None:
    from service.api.fleet import MAX_PLOTTED, _plotted

    members = set(range(1, 2001))
    shown = _plotted(members, {7, 1999})
    assert {7, 1999} <= shown and len(shown) <= MAX_PLOTTED
    assert len(shown) > MAX_PLOTTED * 0.9  # an even sample, not a handful
    assert _plotted({1, 2, 3}, set()) == {1, 2, 3}
