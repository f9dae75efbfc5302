"""``soakcal token list|revoke``, ``--expires-days``, ``schedule add|list|rm``, ``coefficients``."""

from __future__ import annotations

import datetime as dt
import json

import pytest
from test_svc_cli import live_service  # noqa: F401  (the fixture: uvicorn in a thread)

from service.cli import main
from service.db.models import ApiToken, Calibration
from service.db.session import make_session_factory, session_scope


def _last_line(out: str) -> str:
    return out.rstrip("\n").splitlines()[-1]


def test_token_create_with_expiry_list_and_revoke(
    clean_db_url: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("SOAKCAL_DATABASE_URL", clean_db_url)
    assert main(["token", "create", "--role", "viewer", "--name", "lab pc",
                 "--expires-days", "7"]) == 0
    out = capsys.readouterr().out
    assert _last_line(out).startswith("sct_")
    assert main(["token", "create", "--role", "admin"]) == 0
    capsys.readouterr()
    assert main(["token", "list"]) == 0
    listing = capsys.readouterr().out
    assert "lab pc" in listing and listing.count("active") == 2
    in_7_days = dt.datetime.now(dt.UTC) + dt.timedelta(days=7)
    assert f"{in_7_days:%Y-%m-%d}" in listing  # the viewer's expiry (the admin's is "-")
    assert "sct_" not in listing
    assert main(["token", "revoke", "1"]) == 0
    assert "token 1 (viewer, lab pc) revoked" in capsys.readouterr().out
    assert main(["token", "list"]) == 0
    assert "revoked" in capsys.readouterr().out
    factory = make_session_factory(clean_db_url)
    try:
        with factory() as session:
            row = session.get(ApiToken, 1)
            assert row.revoked_at is not None and row.expires_at is not None
    finally:
        factory.kw["bind"].dispose()
    assert main(["token", "revoke", "99"]) == 2
    assert "no token 99" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["0", "-1", "nan", "1e9", "x"])
def test_token_expiry_must_be_a_sensible_number_of_days(
    bad: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["token", "create", "--role", "viewer", "--expires-days", bad])
    assert exit_info.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_schedule_add_list_rm(live_service, capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]  # noqa: F811
    url, token, _ = live_service
    monkeypatch.setenv("SOAKCAL_TOKEN", token)
    assert main(["schedule", "add", "--url", url, "--sensor", "SN-9", "--cron", "0 20 * * 1-5",
                 "--timezone", "Europe/Berlin", "--setpoints=-10,20"]) == 0
    assert "schedule 1: cron '0 20 * * 1-5' (Europe/Berlin)" in capsys.readouterr().out
    assert main(["schedule", "add", "--url", url, "--sensor", "SN-9",
                 "--at", "2031-05-01T22:00:00Z"]) == 0
    assert "once at 2031-05-01 22:00 UTC" in capsys.readouterr().out
    assert main(["schedule", "list", "--url", url]) == 0
    listing = capsys.readouterr().out
    assert "SN-9" in listing and "2031-05-01 22:00" in listing
    assert main(["schedule", "list", "--url", url, "--json"]) == 0
    assert [(s["id"], s["campaign"]["sensor"]) for s in json.loads(capsys.readouterr().out)] \
        == [(1, "SN-9"), (2, "SN-9")]
    assert main(["schedule", "rm", "--url", url, "1"]) == 0
    assert "schedule 1 removed" in capsys.readouterr().out
    assert main(["schedule", "rm", "--url", url, "1"]) == 2
    assert "HTTP 404" in capsys.readouterr().err
    assert main(["schedule", "add", "--url", url, "--sensor", "S", "--cron", "bad"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("soakcal schedule: HTTP 422") and len(err.splitlines()) == 1


def test_schedule_add_needs_exactly_one_trigger(capsys) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(SystemExit) as exit_info:
        main(["schedule", "add", "--sensor", "S"])
    assert exit_info.value.code == 2
    with pytest.raises(SystemExit):
        main(["schedule", "add", "--sensor", "S", "--at", "2030-01-01", "--cron", "* * * * *"])
    assert "not allowed with" in capsys.readouterr().err


def test_coefficients_at_a_temperature(live_service, capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]  # noqa: F811
    url, token, sf = live_service
    monkeypatch.setenv("SOAKCAL_TOKEN", token)
    assert main(["coefficients", "--url", url, "SN/1", "--temperature-c", "25"]) == 2
    assert "HTTP 404" in capsys.readouterr().err
    with session_scope(sf) as session:
        session.add(_identity_calibration("SN-COEF"))
    assert main(["coefficients", "--url", url, "SN-COEF", "--temperature-c", "25"]) == 0
    out = capsys.readouterr().out
    assert "calibration 1 at 25.00 °C" in out
    assert "1.00000000" in out
    assert main(["coefficients", "--url", url, "SN-COEF", "--temperature-c", "80"]) == 2
    assert "HTTP 422" in capsys.readouterr().err
    assert main(["coefficients", "--url", url, "SN-COEF", "--temperature-c", "80",
                 "--extrapolate"]) == 0
    assert "(extrapolated)" in capsys.readouterr().out


def _identity_calibration(serial: str) -> Calibration:
    """A real model document: identity matrix and zero bias at every temperature, 10..40 °C."""
    import numpy as np

    from calibration.model_file import dump_model_dict
    from calibration.thermal import ThermalModel

    coeffs = np.zeros((12, 4))
    coeffs[3:6, 0] = 1.0  # unit scale factors
    model = ThermalModel(coeffs=coeffs, t_centre_c=25.0, t_scale_c=15.0, valid_c=(10.0, 40.0),
                         mode="reference", identifiable=np.ones(12, bool))
    return Calibration(sensor=serial, valid_lo_c=10.0, valid_hi_c=40.0, rmse_ug=1.0,
                       model_version="sfem-cubic-1", model=dump_model_dict(model))
