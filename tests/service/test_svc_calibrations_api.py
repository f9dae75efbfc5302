"""Calibrations: per-sensor list newest first, the stored document, coefficients at T."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service.db.models import Calibration
from service.db.session import session_scope

T0 = dt.datetime(2026, 11, 1, 12, 0, tzinfo=dt.UTC)


def _model_doc(bz_at_centre_g: float = 0.01, bz_slope_g: float = 0.002) -> dict:
    """A real model document: identity matrix, z bias linear in x = (T - 10) / 50."""
    from calibration.model_file import dump_model_dict
    from calibration.thermal import ThermalModel

    coeffs = np.zeros((12, 4))
    coeffs[2, :2] = [bz_at_centre_g, bz_slope_g]  # bz
    coeffs[3:6, 0] = 1.0  # unit scale factors
    model = ThermalModel(
        coeffs=coeffs,
        t_centre_c=10.0,
        t_scale_c=50.0,
        valid_c=(-40.0, 60.0),
        mode="reference",
        identifiable=np.ones(12, bool),
    )
    return dump_model_dict(model)


@pytest.fixture
def calibrations(sf) -> list[int]:  # type: ignore[no-untyped-def]
    """Two calibrations of SN-0001 (older, newer) and one of another sensor."""
    rows = [
        Calibration(
            sensor="SN-0001",
            created_at=T0,
            valid_lo_c=-40,
            valid_hi_c=60,
            rmse_ug=50.0,
            model_version="sfem-cubic-1",
            model=_model_doc(bz_at_centre_g=0.5),
        ),
        Calibration(
            sensor="SN-0001",
            created_at=T0 + dt.timedelta(days=1),
            valid_lo_c=-40,
            valid_hi_c=60,
            rmse_ug=41.2,
            model_version="sfem-cubic-1",
            model=_model_doc(),
        ),
        Calibration(
            sensor="SN-0009",
            created_at=T0,
            valid_lo_c=0,
            valid_hi_c=40,
            rmse_ug=9.0,
            model_version="sfem-cubic-1",
            model=_model_doc(),
        ),
    ]
    with session_scope(sf) as session:
        session.add_all(rows)
        session.flush()
        return [r.id for r in rows]


def test_sensor_calibrations_newest_first(client: TestClient, auth, calibrations) -> None:  # type: ignore[no-untyped-def]
    listed = client.get("/api/v1/sensors/SN-0001/calibrations", headers=auth["viewer"]).json()
    assert [c["id"] for c in listed] == [calibrations[1], calibrations[0]]
    assert listed[0] == {
        "id": calibrations[1],
        "sensor": "SN-0001",
        "campaign_id": None,
        "created_at": "2026-11-02T12:00:00Z",
        "valid_c": [-40.0, 60.0],
        "rmse_ug": 41.2,
        "model_version": "sfem-cubic-1",
    }
    assert client.get("/api/v1/sensors/SN-404/calibrations", headers=auth["viewer"]).json() == []


def test_calibration_document_is_the_stored_model(client: TestClient, auth, calibrations) -> None:  # type: ignore[no-untyped-def]
    response = client.get(f"/api/v1/calibrations/{calibrations[1]}", headers=auth["viewer"])
    assert response.status_code == 200 and response.json() == _model_doc()
    assert client.get("/api/v1/calibrations/999", headers=auth["viewer"]).status_code == 404


def test_coefficients_evaluate_the_latest_model(client: TestClient, auth, calibrations) -> None:  # type: ignore[no-untyped-def]
    response = client.get(
        "/api/v1/sensors/SN-0001/coefficients?temperature_c=35", headers=auth["viewer"]
    )
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["calibration_id"] == calibrations[1] and body["temperature_c"] == 35.0
    np.testing.assert_allclose(body["matrix"], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(body["bias_g"], [0.0, 0.0, 0.01 + 0.002 * 0.5], atol=1e-12)


def test_coefficients_outside_valid_c_are_422_unless_extrapolated(  # type: ignore[no-untyped-def]
    client: TestClient, auth, calibrations
) -> None:
    url = "/api/v1/sensors/SN-0001/coefficients?temperature_c=85"
    response = client.get(url, headers=auth["viewer"])
    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["query", "temperature_c"]
    extrapolated = client.get(url + "&extrapolate=true", headers=auth["viewer"])
    assert extrapolated.status_code == 200 and extrapolated.json()["extrapolated"] is True
    np.testing.assert_allclose(extrapolated.json()["bias_g"][2], 0.01 + 0.002 * 1.5)


def test_coefficients_errors(client: TestClient, auth, calibrations) -> None:  # type: ignore[no-untyped-def]
    base = "/api/v1/sensors/SN-0001/coefficients"
    assert client.get(base, headers=auth["viewer"]).status_code == 422  # temperature_c missing
    assert client.get(base + "?temperature_c=warm", headers=auth["viewer"]).status_code == 422
    missing = client.get(
        "/api/v1/sensors/SN-404/coefficients?temperature_c=20", headers=auth["viewer"]
    )
    assert missing.status_code == 404
    assert client.get(base + "?temperature_c=20").status_code == 401


def test_firmware_export_download_is_what_soakcal_export_writes(  # type: ignore[no-untyped-def]
        client: TestClient, auth, calibrations) -> None:
    from calibration.export import export_text
    from calibration.model_file import load_conditioning_dict, load_model_dict

    url = f"/api/v1/calibrations/{calibrations[1]}/export"
    r = client.get(url, headers=auth["viewer"])
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/x-c")
    assert "attachment" in r.headers["content-disposition"]
    doc = _model_doc()
    expected = export_text(load_model_dict(doc), "c", conditioning=load_conditioning_dict(doc),
                           source_name=f"calibration-{calibrations[1]}.json")
    assert r.text == expected and "soakcal_compensate_f" in r.text
    flat = client.get(url, params={"format": "json-flat"}, headers=auth["viewer"])
    assert flat.status_code == 200 and "coefficients" in flat.text.lower()
    assert client.get(url, params={"format": "pdf"}, headers=auth["viewer"]).status_code == 422
    assert client.get("/api/v1/calibrations/999/export", headers=auth["viewer"]).status_code \
        == 404
    assert client.get(url).status_code == 401
