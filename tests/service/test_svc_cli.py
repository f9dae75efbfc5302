"""The CLI: token create prints the token last; campaign commands talk to a live service."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator

import pytest
from sqlalchemy import select

from service.api.app import create_app
from service.api.auth import hash_token
from service.cli import build_parser, main
from service.config import Settings
from service.db.models import ApiToken, Campaign
from service.db.session import make_session_factory, session_scope
from tests.live_uvicorn import serve_in_thread


def test_token_create_prints_the_token_as_the_last_line(
    clean_db_url: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("SOAKCAL_DATABASE_URL", clean_db_url)
    assert main(["token", "create", "--role", "operator", "--name", "night shift"]) == 0
    token = capsys.readouterr().out.rstrip("\n").splitlines()[-1]
    factory = make_session_factory(clean_db_url)
    try:
        with factory() as session:
            row = session.scalar(select(ApiToken).where(ApiToken.token_hash == hash_token(token)))
    finally:
        factory.kw["bind"].dispose()
    assert row is not None and row.role == "operator" and row.name == "night shift"


def test_bad_input_exits_2_with_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["token", "create", "--role", "superuser"])
    assert exit_info.value.code == 2
    assert "superuser" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["serve", "--help"],
        ["token", "create", "--help"],
        ["campaign", "watch", "--help"],
        ["calibrate", "--help"],
        ["compensate", "--help"],
        ["diagnose", "--help"],
        ["import", "--help"],
        ["demo", "--help"],
    ],
)
def test_help_works_everywhere(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 0


def test_delegated_subcommands_parse_the_contract_arguments() -> None:
    parser = build_parser()
    args = parser.parse_args(
        [
            "diagnose",
            "run.csv",
            "--model",
            "m.json",
            "--json",
            "--seed",
            "3",
            "--n-null",
            "50",
            "--report-dir",
            "out",
        ]
    )
    assert (args.recording, args.model, args.json, args.seed, args.n_null) == (
        "run.csv",
        "m.json",
        True,
        3,
        50,
    )
    args = parser.parse_args(
        [
            "import",
            "--format",
            "xyz",
            "raw.txt",
            "-o",
            "rec.csv",
            "--min-static-s",
            "2.5",
            "--threshold",
            "0.01",
        ]
    )
    assert (args.format, args.raw, args.output, args.min_static_s) == (
        "xyz",
        "raw.txt",
        "rec.csv",
        2.5,
    )


def test_a_missing_module_is_a_clear_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "service.demo", None)  # None in sys.modules: ImportError
    assert main(["demo"]) == 1
    assert "soakcal demo: not available" in capsys.readouterr().err


@pytest.fixture
def live_service(clean_db_url: str) -> Iterator[tuple[str, str, object]]:
    """uvicorn in a thread on a free port, engine off; yields (url, operator token, sf)."""
    settings = Settings(
        database_url=clean_db_url,
        run_engine=False,
        run_scheduler=False,
        migrate=False,
        events_poll_s=0.02,
    )
    with serve_in_thread(create_app(settings)) as url:
        sf = make_session_factory(clean_db_url)
        with session_scope(sf) as session:
            from service.api.auth import create_token

            token = create_token(session, "operator")
        yield url, token, sf
        sf.kw["bind"].dispose()


def test_campaign_start_list_pause_and_watch(live_service, capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    url, token, sf = live_service
    monkeypatch.setenv("SOAKCAL_TOKEN", token)
    assert main(["campaign", "start", "--url", url, "--sensor", "SN-7", "--setpoints=-10,20"]) == 0
    assert "campaign 1 queued" in capsys.readouterr().out
    assert main(["campaign", "list", "--url", url, "--state", "queued"]) == 0
    assert "SN-7" in capsys.readouterr().out
    assert main(["campaign", "list", "--url", url, "--state", "queued", "--json"]) == 0
    assert [c["sensor"] for c in json.loads(capsys.readouterr().out)] == ["SN-7"]
    assert main(["campaign", "pause", "--url", url, "1"]) == 0
    assert "campaign 1 paused" in capsys.readouterr().out
    assert main(["campaign", "pause", "--url", url, "1"]) == 2  # 409: already paused
    assert "HTTP 409" in capsys.readouterr().err
    assert main(["campaign", "start", "--url", url, "--sensor", "S", "--setpoints", "500"]) == 2
    assert "setpoints_c.0" in capsys.readouterr().err

    def finish() -> None:
        time.sleep(0.3)
        with session_scope(sf) as session:
            campaign = session.get(Campaign, 1)
            campaign.state = "completed"
            campaign.progress = {"phase": "fitting", "fraction": 1.0, "eta_s": 0.0}
            campaign.calibration_id = 5

    threading.Thread(target=finish).start()
    assert main(["campaign", "watch", "--url", url, "1"]) == 0
    out = capsys.readouterr().out
    assert "step 0 of 0..1" in out and "100%" in out and "completed" in out  # 0-based, as the API
    assert "calibration 5 of sensor SN-7" in out
    # stdout is not a terminal here (a log file, a pipe): plain lines, no redrawing
    assert "\r" not in out and "\x1b" not in out
    lines = out.splitlines()
    assert lines[-1] == "calibration 5 of sensor SN-7: soakcal coefficients SN-7 --temperature-c T"
    assert all(line.startswith("[") for line in lines[:-1])  # progress lines, then the end
    assert lines[-2].startswith("[########################] 100% step 0 of 0..1 fitting")
    assert lines[-2].endswith("completed")
    assert len(lines) == len(set(lines))  # one line per change, not one per poll


def test_campaign_start_from_a_spec_file_and_negative_setpoints_without_equals(
        live_service, capsys, monkeypatch, tmp_path) -> None:  # type: ignore[no-untyped-def]
    url, token, _ = live_service
    monkeypatch.setenv("SOAKCAL_TOKEN", token)
    spec = tmp_path / "night.json"
    spec.write_text(json.dumps({"sensor": "SN-SPEC", "setpoints_c": [-20, 0, 20],
                                "positions": "six", "soak_min": 45, "stability": "fixed"}))
    assert main(["campaign", "start", "--url", url, "--spec", str(spec)]) == 0
    assert "queued on rig sim" in capsys.readouterr().out
    assert main(["campaign", "start", "--url", url, "--spec", str(spec), "--sensor", "SN-B",
                 "--setpoints", "-40,20"]) == 0
    capsys.readouterr()
    assert main(["campaign", "list", "--url", url, "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [(c["sensor"], c["spec"]["setpoints_c"], c["spec"]["soak_min"]) for c in listed] == [
        ("SN-B", [-40.0, 20.0], 45), ("SN-SPEC", [-20, 0, 20], 45)]
    # what a person reads when the list or the file is wrong
    with pytest.raises(SystemExit):
        main(["campaign", "start", "--url", url, "--sensor", "S", "--setpoints", "-40,x"])
    assert ("argument --setpoints: 'x' is not a temperature; expected °C numbers separated by "
            "commas, e.g. -40,-20,0") in capsys.readouterr().err
    spec.write_text(json.dumps({"positions": "six"}))
    assert main(["campaign", "start", "--url", url, "--spec", str(spec)]) == 2
    assert capsys.readouterr().err == (f"soakcal campaign start: {spec}: names no sensor; add "
                                       '"sensor" to the file or give --sensor SERIAL\n')
    spec.write_text("{\n  \"sensor\": \"S\",\n}")
    assert main(["campaign", "start", "--url", url, "--spec", str(spec)]) == 2
    assert f"{spec}:3:1: not JSON" in capsys.readouterr().err


def test_a_closed_pipe_ends_the_output_quietly(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """`soakcal ... | head`: the reader left; no BrokenPipeError traceback on the terminal."""
    import os
    import subprocess
    import sys

    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line is written
    try:
        done = subprocess.run(
            [sys.executable, "-m", "service.cli", "campaign", "plan", "--positions", "six",
             "--setpoints", "-40,20"], stdout=write_end, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "SOAKCAL_DATABASE_URL": f"sqlite:///{tmp_path / 'none.db'}"},
            timeout=120)
    finally:
        os.close(write_end)
    assert "Traceback" not in done.stderr and "BrokenPipe" not in done.stderr, done.stderr
    assert done.returncode == 0


def test_campaign_commands_without_a_token_exit_2(live_service, capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    url, _, _ = live_service
    monkeypatch.delenv("SOAKCAL_TOKEN", raising=False)
    assert main(["campaign", "list", "--url", url]) == 2
    assert "HTTP 401" in capsys.readouterr().err


def test_unreachable_service_exits_1(capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["campaign", "list", "--url", "http://127.0.0.1:1", "--token", "x"]) == 1
    assert "cannot reach" in capsys.readouterr().err
