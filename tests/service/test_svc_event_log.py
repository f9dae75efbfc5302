"""Engine and ops events: one structured (logfmt) INFO line each."""

from __future__ import annotations

import logging

import pytest

from service.engine import store
from service.event_log import format_event, log_event


def test_format_is_one_logfmt_line_with_units_in_the_keys() -> None:
    line = format_event(
        "campaign suspended", campaign=3, reason='chamber: timeout\n"read"', chamber_c=-19.98,
        ok=True, missing=None,
    )
    assert line == (
        'event="campaign suspended" campaign=3 reason="chamber: timeout\\n\\"read\\"" '
        "chamber_c=-19.98 ok=true"
    )
    assert "\n" not in line


def test_log_event_is_info_on_soakcal_events(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="soakcal.events"):
        log_event("soak ended", campaign=1, step=2)
    (record,) = caplog.records
    assert record.name == "soakcal.events" and record.levelno == logging.INFO
    assert record.getMessage() == 'event="soak ended" campaign=1 step=2'


def test_the_store_logs_state_changes_suspensions_and_soak_ends(
    clean_db_url: str, caplog: pytest.LogCaptureFixture
) -> None:
    from service.db.models import Campaign, Rig
    from service.db.session import make_session_factory, session_scope

    sf = make_session_factory(clean_db_url)
    try:
        with session_scope(sf) as session:
            session.add(Rig(name="sim"))
            session.flush()
            session.add(Campaign(id=7, rig="sim", sensor="SN-1", state="queued", spec={}))
        with caplog.at_level(logging.INFO, logger="soakcal.events"):
            assert store.transition(sf, 7, "running")
            store.update_campaign(sf, 7, suspended_reason="chamber: no reply")
            store.update_campaign(sf, 7, suspended_reason=None)
            store.update_campaign(sf, 7, progress={"fraction": 0.5})  # not an event
            store.put_step_log(sf, 7, {"step": 0, "setpoint_c": -20.0, "soak_s": 1800.0,
                                       "reason": "stable"})
            assert not store.transition(sf, 7, "queued")  # refused: no line
            assert store.transition(sf, 7, "failed", error="chamber lost")
    finally:
        sf.kw["bind"].dispose()
    lines = [r.getMessage() for r in caplog.records if r.name == "soakcal.events"]
    assert lines == [
        'event="campaign started" campaign=7 state=running was=queued',
        'event="campaign suspended" campaign=7 reason="chamber: no reply"',
        'event="campaign unsuspended" campaign=7',
        'event="soak ended" campaign=7 step=0 setpoint_c=-20 soak_s=1800 reason=stable',
        'event="campaign ended" campaign=7 state=failed was=running error="chamber lost"',
    ]
