"""One configuration home: every subcommand finds the same database from any folder."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from service.cli import main
from service.config import ConfigError, check_database_url, database_choice, home_dir


def test_the_suite_runs_in_a_throw_away_home() -> None:
    assert Path(os.environ["SOAKCAL_HOME"]).resolve() != (Path.home() / ".local/share/soakcal")
    assert "SOAKCAL_DATABASE_URL" not in os.environ


def test_token_create_uses_the_home_from_any_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    home = tmp_path / "home"
    monkeypatch.setenv("SOAKCAL_HOME", str(home))
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        monkeypatch.chdir(tmp_path / folder)
        assert main(["token", "create", "--role", "viewer"]) == 0
        captured = capsys.readouterr()
        assert f"database sqlite:///{home / 'soakcal.db'} (in SOAKCAL_HOME)" in captured.err
    assert (home / "soakcal.db").exists()
    assert not list((tmp_path / "a").iterdir()) and not list((tmp_path / "b").iterdir())


def test_the_default_home_is_per_user(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SOAKCAL_HOME")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert home_dir() == (tmp_path / "xdg" / "soakcal").resolve()
    url, why = database_choice()
    assert url == f"sqlite:///{tmp_path / 'xdg' / 'soakcal' / 'soakcal.db'}"
    assert "per-user" in why
    monkeypatch.setenv("SOAKCAL_DATABASE_URL", "postgresql+psycopg://u@h/db")
    assert database_choice() == ("postgresql+psycopg://u@h/db", "from SOAKCAL_DATABASE_URL")


@pytest.mark.parametrize(
    ("url", "part"),
    [
        ("nonsense", "not a URL"),
        ("mysql://u@h/db", "'mysql' is not supported"),
        ("postgresql+nodriver://u@h/db", "no driver 'nodriver'"),
        ("postgresql+psycopg://u@h:99999/db", "port 99999"),
        ("postgresql+psycopg://u@h:5432", "no database name"),
    ],
)
def test_a_bad_database_url_names_the_wrong_part(url: str, part: str) -> None:
    with pytest.raises(ConfigError, match=part):
        check_database_url(url)


@pytest.mark.parametrize("command", [["serve"], ["token", "create", "--role", "admin"],
                                     ["campaign", "plan"]])
def test_a_bad_database_url_is_one_line_and_exit_2(
        command: list[str], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("SOAKCAL_DATABASE_URL", "mysql://u@h/db")
    assert main(command) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "SOAKCAL_DATABASE_URL" in err[0] and "mysql" in err[0]


def test_an_unreachable_database_is_one_line_and_exit_2(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("SOAKCAL_DATABASE_URL", "postgresql+psycopg://u@127.0.0.1:1/db")
    assert main(["token", "create", "--role", "admin"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "cannot open the database" in err[1] and "Traceback" not in err[1]


def test_campaign_plan_prints_the_summary_or_the_reason(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("SOAKCAL_HOME", str(tmp_path))
    assert main(["campaign", "plan", "--rig", "sim", "--positions", "six",
                 "--setpoints=-10,20"]) == 0
    out = capsys.readouterr().out
    assert "2 steps × 6 positions, reference mode, predicted duration" in out
    assert not (tmp_path / "soakcal.db").exists()  # looking does not create a database

    assert main(["campaign", "plan", "--positions", "sphere1"]) == 2
    err = capsys.readouterr().err
    assert "positions: position schedule 'sphere1'" in err and "reference mode" in err
    assert main(["campaign", "plan", "--setpoints=-90,20"]) == 2
    assert "setpoints_c.0: setpoint -90 °C is outside" in capsys.readouterr().err
    assert main(["campaign", "plan", "--samples-per-position", "200000"]) == 2
    assert "samples_per_position" in capsys.readouterr().err
    assert main(["campaign", "plan", "--rig", "nope"]) == 2
    assert "unknown rig 'nope'" in capsys.readouterr().err

    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"rig": "sim", "sensor": "SN-1", "positions": "cube14",
                                "soak_min": 10, "stability": "fixed"}))
    assert main(["campaign", "plan", "--spec", str(spec), "--json"]) == 0
    verdict = json.loads(capsys.readouterr().out)
    assert verdict["ok"] and verdict["positions"] == 14 and verdict["predicted_duration_s"] > 0
    spec.write_text('{"positions": ')
    assert main(["campaign", "plan", "--spec", str(spec)]) == 2
    assert f"{spec}:1:" in capsys.readouterr().err


def test_campaign_plan_reads_rigs_from_the_service_database(
        clean_db_url: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from service.db.models import Rig
    from service.db.session import make_session_factory, session_scope

    factory = make_session_factory(clean_db_url)
    try:
        with session_scope(factory) as session:
            session.add(Rig(name="lab-1", chamber={"driver": "sim", "range_c": [-40, 85]},
                            turntable={}, sensors=[]))
    finally:
        factory.kw["bind"].dispose()
    monkeypatch.setenv("SOAKCAL_DATABASE_URL", clean_db_url)
    assert main(["campaign", "plan", "--rig", "lab-1", "--setpoints=-40,85"]) == 0
    assert main(["campaign", "plan", "--rig", "lab-1", "--setpoints=-50,20"]) == 2
    assert "[-40, 85] °C" in capsys.readouterr().err
