"""Rigs on several hosts: ``serve --rigs``, ``soakcal worker``, and the manager's rig filter."""

from __future__ import annotations

import pytest
from engine_helpers import SMALL_SPEC, add_campaign

from service.cli import build_parser, main
from service.config import ENGINE_RIGS_ENV, Settings, parse_rigs
from service.engine.manager import CampaignManager


def test_parse_rigs() -> None:
    assert parse_rigs(None) is None and parse_rigs("") is None
    assert parse_rigs("none") == frozenset()
    assert parse_rigs("lab-1, lab-2") == frozenset({"lab-1", "lab-2"})
    with pytest.raises(ValueError, match="entry 2 'a b'"):
        parse_rigs("lab-1,a b")


def test_cli_accepts_rigs_and_refuses_bad_names(capsys) -> None:  # type: ignore[no-untyped-def]
    args = build_parser().parse_args(["serve", "--rigs", "lab-1,lab-2"])
    assert args.rigs == "lab-1,lab-2"
    assert build_parser().parse_args(["worker", "--rigs", "lab-3"]).rigs == "lab-3"
    with pytest.raises(SystemExit) as exit_:
        main(["worker", "--rigs", "lab 3"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'lab 3' is not a rig name" in err
    with pytest.raises(SystemExit):
        main(["worker"])  # --rigs is required: a worker names its host's rigs


def test_settings_read_the_rigs_serve_was_given(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setenv(ENGINE_RIGS_ENV, "none")
    assert Settings().engine_rigs == frozenset()
    monkeypatch.setenv(ENGINE_RIGS_ENV, "lab-1")
    assert Settings().engine_rigs == frozenset({"lab-1"})
    monkeypatch.delenv(ENGINE_RIGS_ENV)
    assert Settings().engine_rigs is None


async def test_manager_runs_only_its_rigs(sf) -> None:  # type: ignore[no-untyped-def]
    from service.engine import store

    here = add_campaign(sf, SMALL_SPEC, rig="lab-1")
    there = add_campaign(sf, SMALL_SPEC, rig="lab-2")
    mine = CampaignManager(sf, owner="host-a", rigs={"lab-1"})
    try:
        await mine.run_once()
        assert set(mine._runs) == {"lab-1"}
    finally:
        await mine.stop()
    assert store.load_campaign(sf, there).state == "queued"  # another host's rig: untouched
    assert store.load_campaign(sf, here).state in ("queued", "running")


def test_worker_process_drives_only_its_rigs_and_stops_cleanly(sf, migrated_db_url) -> None:  # type: ignore[no-untyped-def]
    """`soakcal worker --rigs lab-1` as a real process: it runs lab-1's campaign, never
    lab-2's, and SIGTERM leaves the campaign `running` for the next holder, lease released."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from sqlalchemy import select

    from service.db.models import Measurement, RigLease
    from service.engine import store

    if not migrated_db_url.startswith("sqlite"):
        pytest.skip("one database flavour is enough for the process plumbing")
    here = add_campaign(sf, SMALL_SPEC, rig="lab-1")
    there = add_campaign(sf, SMALL_SPEC, rig="lab-2")
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root), "SOAKCAL_DATABASE_URL": migrated_db_url}
    p = subprocess.Popen([sys.executable, "-m", "service.cli", "worker", "--rigs", "lab-1",
                          "--sim-speed", "3000"], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and p.poll() is None:
            with sf() as s:
                n = len(s.execute(select(Measurement.id)
                                  .where(Measurement.campaign_id == here)).all())
            if n >= 1:
                break
            time.sleep(0.1)
        assert p.poll() is None and n >= 1, p.communicate()[0] if p.poll() is not None else n
        assert store.load_campaign(sf, there).state == "queued"
        p.send_signal(signal.SIGTERM)
        out, _ = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, out
    assert "engine for rigs: lab-1" in out
    assert store.load_campaign(sf, here).state == "running"
    with sf() as s:
        assert s.get(RigLease, "lab-1") is None
