"""``soakcal campaign place`` and the placement lines of ``campaign watch`` (manual rigs)."""

from __future__ import annotations

import threading
import time

import numpy as np
from test_svc_cli import live_service  # noqa: F401  (the fixture: uvicorn in a thread)

from service import cli_placement
from service.cli import main
from service.db.models import Campaign, PlacementRequest, Rig
from service.db.session import session_scope
from service.engine.placement import PlacementBoard


def _running_campaign(sf) -> int:  # type: ignore[no-untyped-def]
    with session_scope(sf) as s:
        if s.query(Rig).filter_by(name="bench").first() is None:
            s.add(Rig(name="bench", chamber={"driver": "sim"}, turntable={"driver": "manual"},
                      sensors=[]))
            s.flush()
        c = Campaign(rig="bench", sensor="SN-1", spec={"positions": "six"}, state="running",
                     progress={}, steps_log=[])
        s.add(c)
        s.flush()
        return c.id


def test_place_confirms_the_pending_position_and_refuses_a_wrong_one(
        live_service, capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]  # noqa: F811
    url, token, sf = live_service
    monkeypatch.setenv("SOAKCAL_TOKEN", token)
    cid = _running_campaign(sf)
    assert main(["campaign", "place", "--url", url, str(cid)]) == 2
    assert "no placement is pending" in capsys.readouterr().err
    PlacementBoard(sf, "bench").publish(np.array([0.0, 0.0, -1.0]))  # position 5: -z
    assert main(["campaign", "place", "--url", url, str(cid), "--position", "4"]) == 2
    assert "position 5 is asked, not 4" in capsys.readouterr().err
    assert main(["campaign", "place", "--url", url, str(cid)]) == 0
    assert "position 5 confirmed (face -z up" in capsys.readouterr().out
    with session_scope(sf) as s:
        assert s.get(PlacementRequest, cid).state == "confirmed"


def test_watch_prints_the_pending_instruction(live_service, capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]  # noqa: F811
    url, token, sf = live_service
    monkeypatch.setenv("SOAKCAL_TOKEN", token)
    cid = _running_campaign(sf)
    with session_scope(sf) as s:
        s.get(Campaign, cid).progress = {"phase": "positions", "fraction": 0.1, "step": 0,
                                         "steps": 1, "eta_s": 60.0}
    PlacementBoard(sf, "bench").publish(np.array([1.0, 0.0, 0.0]))
    # The campaign completes once watch has described the request (a fixed 1-s sleep lost
    # the race on a loaded machine: watch's first poll came after the completion). If it
    # never does, the campaign completes after 30 s and the assertions below fail.
    described = threading.Event()
    describe = cli_placement.describe_request

    def describe_and_signal(request: dict) -> str:
        text = describe(request)
        described.set()
        return text

    monkeypatch.setattr(cli_placement, "describe_request", describe_and_signal)

    def finish() -> None:
        described.wait(timeout=30.0)
        time.sleep(0.2)  # watch prints what it described before it polls again
        with session_scope(sf) as s:
            c = s.get(Campaign, cid)
            c.state = "completed"
            c.progress = {"phase": "fitting", "fraction": 1.0, "eta_s": 0.0, "step": 0,
                          "steps": 1}

    threading.Thread(target=finish).start()
    main(["campaign", "watch", "--url", url, str(cid)])
    out = capsys.readouterr().out
    assert "placement of position 0 asked" in out and "face +x up" in out
    assert f"soakcal campaign place {cid} --position 0" in out
