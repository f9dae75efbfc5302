"""recording.csv (format v1, time order, empty cells for None) and the SSE progress stream."""

from __future__ import annotations

import csv
import io
import json
import threading
import time

from fastapi.testclient import TestClient
from svc_helpers import new_campaign, set_campaign

from service.api.recording_csv import RECORDING_COLUMNS
from service.db.models import Measurement
from service.db.session import session_scope


def _measurement(cid: int, step: int, position: int, t_s: float, **extra) -> Measurement:  # type: ignore[no-untyped-def]
    values = dict(
        campaign_id=cid,
        step=step,
        position=position,
        t_s=t_s,
        setpoint_c=-40.0,
        chamber_c=-39.99,
        sensor_c=-38.75,
        ref_x=0.0,
        ref_y=0.0,
        ref_z=1.0,
        ax=0.00421993386,
        ay=0.0197724144,
        az=0.992438681,
        n=200,
        sd_x=1e-4,
        sd_y=1e-4,
        sd_z=1e-4,
    )
    values.update(extra)
    return Measurement(**values)


def test_recording_csv_is_format_v1_in_time_order(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    cid = new_campaign(client, auth["operator"])["id"]
    with session_scope(sf) as session:  # stored out of order on purpose
        session.add(_measurement(cid, 0, 1, 5610.0, sd_x=None, sd_y=None, sd_z=None))
        session.add(_measurement(cid, 0, 0, 5570.0))
    response = client.get(f"/api/v1/campaigns/{cid}/recording.csv", headers=auth["viewer"])
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(response.text)))
    assert tuple(rows[0]) == RECORDING_COLUMNS == (
        "t_s", "step", "setpoint_c", "chamber_c", "sensor_c", "position", "visit", "ref_x",
        "ref_y", "ref_z", "ax", "ay", "az", "n", "sd_x", "sd_y", "sd_z")  # fmt: skip
    assert [r["t_s"] for r in rows] == ["5570.0", "5610.0"]
    assert [(r["position"], r["visit"]) for r in rows] == [("0", "0"), ("1", "1")]
    assert float(rows[0]["ax"]) == 0.00421993386 and rows[0]["n"] == "200"
    assert rows[1]["sd_x"] == ""  # not recorded


def test_visit_counts_each_step_s_rows_in_time_order_whatever_their_position(  # type: ignore[no-untyped-def]
        client: TestClient, auth, sf) -> None:
    cid = new_campaign(client, auth["operator"])["id"]
    with session_scope(sf) as session:  # a travel order: position 5, then 2, then 0
        for step, position, t_s in ((0, 5, 100.0), (0, 2, 130.0), (1, 0, 900.0), (0, 0, 160.0)):
            session.add(_measurement(cid, step, position, t_s))
    text = client.get(f"/api/v1/campaigns/{cid}/recording.csv", headers=auth["viewer"]).text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert [(r["step"], r["position"], r["visit"]) for r in rows] == [
        ("0", "5", "0"), ("0", "2", "1"), ("0", "0", "2"), ("1", "0", "0")]


def test_recording_of_a_fresh_campaign_is_just_the_header(client: TestClient, auth) -> None:  # type: ignore[no-untyped-def]
    cid = new_campaign(client, auth["operator"])["id"]
    text = client.get(f"/api/v1/campaigns/{cid}/recording.csv", headers=auth["viewer"]).text
    assert text == ",".join(RECORDING_COLUMNS) + "\n"


def _parse_sse(text: str) -> list[tuple[str, dict]]:
    events = []
    for block in text.strip().split("\n\n"):
        lines = [line for line in block.splitlines() if not line.startswith(":")]
        if not lines:
            continue
        kind = next(line[6:].strip() for line in lines if line.startswith("event:"))
        data = "\n".join(line[5:].strip() for line in lines if line.startswith("data:"))
        events.append((kind, json.loads(data)))
    return events


def test_events_follow_progress_and_close_at_a_terminal_state(client: TestClient, auth, sf) -> None:  # type: ignore[no-untyped-def]
    cid = new_campaign(client, auth["operator"])["id"]

    def runner() -> None:  # plays the engine in "another process": only DB writes
        time.sleep(0.2)
        set_campaign(sf, cid, state="running", progress={"phase": "ramp", "chamber_c": 20.0})
        time.sleep(0.2)
        set_campaign(sf, cid, progress={"phase": "soak", "chamber_c": -39.8, "fraction": 0.1})
        time.sleep(0.2)
        set_campaign(sf, cid, state="completed", progress={"phase": "fitting", "fraction": 1.0})

    thread = threading.Thread(target=runner)
    thread.start()
    started = time.monotonic()
    response = client.get(f"/api/v1/campaigns/{cid}/events", headers=auth["viewer"])
    thread.join()
    assert time.monotonic() - started < 10  # it closed by itself
    assert response.headers["content-type"].startswith("text/event-stream")
    events = _parse_sse(response.text)
    states = [data["state"] for kind, data in events if kind == "progress"]
    phases = [data["progress"]["phase"] for kind, data in events if kind == "progress"]
    assert states[0] == "queued" and states[-1] == "completed"
    assert "running" in states and "soak" in phases
    assert len(states) == len({json.dumps(d) for k, d in events if k == "progress"})  # no repeats
    assert events[-1] == (
        "end",
        {"id": cid, "state": "completed", "error": None, "calibration_id": None},
    )
