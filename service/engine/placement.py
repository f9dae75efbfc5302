"""Hand-placed fixtures: the operator's placement requests, kept in the database.

A lab without a turntable places the sensor by hand on a cube or a tilt
fixture (docs/manual-fixtures.md). The pure geometry — the plain-language
instruction for a direction and the check of a capture against it — lives in
:mod:`calibration.placement` (the drivers use it too); this module keeps the
pending request in the ``placement_requests`` table (:class:`PlacementBoard`)
so it survives a restart and the REST API / CLI can show and confirm it, and
wires a manual rig into the engine (:func:`manual_devices`,
:func:`hand_placed_references`, :func:`hand_placed_calibrate`).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from calibration.placement import instruction_for, sketch_for
from service.db.models import Campaign, PlacementRequest

if TYPE_CHECKING:
    from service.engine.calibrate import CalibrationRow


class PlacementConflict(ValueError):
    """Nothing pending, or the confirmed position is not the one asked (API 409)."""


def request_dict(row: PlacementRequest | None) -> dict[str, Any] | None:
    """JSON form of a request (the API's and CLI's view)."""
    if row is None:
        return None
    return {
        "campaign_id": row.campaign_id, "seq": row.seq, "position": row.position,
        "ref_g": [row.ref_x, row.ref_y, row.ref_z], "instruction": row.instruction,
        "sketch": row.sketch, "reason": row.reason, "state": row.state,
        "requested_at": row.requested_at.isoformat() if row.requested_at else None,
        "confirmed_at": row.confirmed_at.isoformat() if row.confirmed_at else None,
    }


def read_request(session: Session, campaign_id: int) -> dict[str, Any] | None:
    return request_dict(session.get(PlacementRequest, campaign_id))


def confirm_request(session: Session, campaign_id: int, position: int | None) -> dict[str, Any]:
    """The operator says the sensor is placed: ``pending`` → ``confirmed`` (caller commits)."""
    row = session.get(PlacementRequest, campaign_id)
    if row is None or row.state != "pending":
        raise PlacementConflict(f"campaign {campaign_id}: no placement is pending")
    if position is not None and position != row.position:
        raise PlacementConflict(
            f"campaign {campaign_id}: position {row.position} is asked, not {position}")
    row.state = "confirmed"
    row.confirmed_at = dt.datetime.now(dt.UTC)
    session.flush()
    out = request_dict(row)
    assert out is not None
    return out


class PlacementBoard:
    """The driver's side of the request table: publish, poll, re-issue, accept.

    ``campaign_for`` returns the campaign the rig runs now (the driver is opened
    per rig, not per campaign); by default the newest ``running`` one on the rig.
    """

    def __init__(self, sf: sessionmaker[Session], rig_name: str,
                 campaign_for: Callable[[], int | None] | None = None) -> None:
        self.sf = sf
        self.rig_name = rig_name
        self.campaign_for = campaign_for or self._running_campaign

    def _running_campaign(self) -> int | None:
        with self.sf() as s:
            return s.execute(select(Campaign.id).where(
                Campaign.rig == self.rig_name, Campaign.state == "running")
                .order_by(Campaign.id.desc())).scalars().first()

    def _position_of(self, s: Session, campaign_id: int, ref_g: np.ndarray) -> int:
        """Index of the schedule position nearest ``ref_g`` (the number the operator confirms)."""
        from service.engine.spec import schedule_refs

        camp = s.get(Campaign, campaign_id)
        try:
            refs = schedule_refs(str((camp.spec or {}).get("positions", "table1")))
        except (ValueError, AttributeError):
            return 0
        refs = refs / np.linalg.norm(refs, axis=1, keepdims=True)
        return int(np.argmax(refs @ (ref_g / np.linalg.norm(ref_g))))

    def publish(self, ref_g: np.ndarray, reason: str | None = None,
                instruction: str | None = None) -> dict[str, Any] | None:
        """Ask for ``ref_g`` (again, with ``reason``); keeps an identical open request as is.
        ``instruction``: what to do, when not placing the whole fixture (a hand axis)."""
        cid = self.campaign_for()
        if cid is None:
            return None
        r = np.asarray(ref_g, float) / np.linalg.norm(ref_g)
        with self.sf() as s:
            row = s.get(PlacementRequest, cid)
            same = row is not None and np.allclose([row.ref_x, row.ref_y, row.ref_z], r, atol=1e-9)
            if same and reason is None and row is not None and row.state in ("pending",
                                                                              "confirmed"):
                return request_dict(row)  # the engine re-commanded the same move: keep it
            position = self._position_of(s, cid, r)  # before add(): no half-filled autoflush
            if row is None:
                row = PlacementRequest(campaign_id=cid, seq=0)
                s.add(row)
            row.seq = (row.seq or 0) + 1
            row.position = position
            row.ref_x, row.ref_y, row.ref_z = (float(v) for v in r)
            row.instruction = instruction or instruction_for(r)
            row.sketch = sketch_for(r)
            row.reason = reason
            row.state = "pending"
            row.requested_at = dt.datetime.now(dt.UTC)
            row.confirmed_at = None
            s.commit()
            return request_dict(row)

    def state(self) -> str | None:
        cid = self.campaign_for()
        if cid is None:
            return None
        with self.sf() as s:
            row = s.get(PlacementRequest, cid)
            return None if row is None else row.state

    def accept(self) -> None:
        cid = self.campaign_for()
        with self.sf() as s:
            row = s.get(PlacementRequest, cid) if cid is not None else None
            if row is not None:
                row.state = "accepted"
                s.commit()


def manual_devices(rig: dict[str, Any], devices: Any, sf: sessionmaker[Session] | None = None
                   ) -> Any:
    """``devices`` with the table replaced by a :class:`drivers.manual_table.ManualTurntable`.

    The board writes to the service's database (``sf``, else the URL the service
    resolves); the driver checks each placement with the rig's accelerometer.
    """
    from dataclasses import replace

    from drivers.geometry import angles_for_reference
    from drivers.manual_table import ManualTurntable
    from service.db.session import make_session_factory

    board = PlacementBoard(sf or make_session_factory(), str(rig.get("name", "")))
    cfg = rig.get("turntable") or {}
    table = ManualTurntable(board, devices.accelerometer,
                            check_samples=int(cfg.get("check_samples", 64)),
                            noise_g=float(cfg.get("noise_g", 0.2e-3)))
    # No pose_for: the operator places the asked direction, the heading about gravity is
    # theirs, so the angles here are a label, not a pose (no ``pose_q*`` recorded).
    return replace(devices, turntable=table,
                   angles_for=lambda ref: tuple(angles_for_reference(np.asarray(ref), 3)),
                   pose_for=None)


def hand_placed_references(turntable: dict[str, Any] | None) -> bool:
    """The rig's reference directions are known only to a hand placement's tolerance, so
    its campaigns are fitted with ``ref_tol_deg`` (:func:`hand_placed_calibrate`): a hand-
    placed fixture, or a motorised stage whose second axis is set by hand. An indexer's
    repeatability, its steps' accuracy and the plate's play when locked (arc-minutes at
    best, a degree on a protractor) are far above σ/g of an averaged position (~10⁻⁵), so
    taken as exact they would turn into misalignment (docs/manual-fixtures.md, "The fit")."""
    from service.engine.rigs import has_hand_axis

    table = turntable or {}
    return table.get("driver") == "manual" or has_hand_axis(table)


def hand_placed_calibrate(calibrate: Callable[[dict[str, list[float]], dict[str, Any]],
                                              CalibrationRow] | None = None,
                          tol_deg: float | None = None
                          ) -> Callable[[dict[str, list[float]], dict[str, Any]], CalibrationRow]:
    """The engine's calibrate step for a manual rig: every row gets ``ref_tol_deg``.

    A hand placement is good to a degree or two, not to the table's arc-seconds;
    docs/fit-honesty.md ("Hand-placed references") fits such rows with the
    labels as a prior instead of exact data. ``tol_deg`` defaults to
    :data:`calibration.placement.HAND_HELD_TOL_DEG` (2°). The runner takes it
    as its ``calibrate=`` argument (docs/manual-fixtures.md, "Wiring").
    """
    from calibration.placement import HAND_HELD_TOL_DEG, REF_TOL_COLUMN
    from service.engine.calibrate import calibrate_columns

    inner = calibrate or calibrate_columns
    tol = HAND_HELD_TOL_DEG if tol_deg is None else float(tol_deg)

    def run(columns: dict[str, list[float]], provenance: dict[str, Any]) -> CalibrationRow:
        n = len(columns["t_s"])
        with_tol = {**columns, REF_TOL_COLUMN: [tol] * n}
        return inner(with_tol, {**provenance, REF_TOL_COLUMN: tol, "placement": "manual"})

    return run
