"""Hand-placed fixtures: what to ask the operator, whether the sensor is where asked.

A lab without a turntable places the sensor by hand on a cube or a tilt
fixture (docs/manual-fixtures.md). The schedule gives each position as the
direction of the specific force in the sensor frame (seed paper eq. (1): a
static sensor measures f = -g rotated into the sensor frame, |f| = 1 g); this
module turns that direction into a plain-language instruction, checks a short
capture against it (:func:`check_placement`), and keeps the pending request in
the ``placement_requests`` table (:class:`PlacementBoard`) so it survives a
restart and the REST API / CLI can show and confirm it.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from service.db.models import Campaign, PlacementRequest

AXES = ("x", "y", "z")
FACE_UP_DEG = 80.0  # an axis this far above the horizontal: "face +z up"
MAX_ANGLE_DEG = 15.0  # measured gravity further than this from the asked direction: re-ask
STATIC_FACTOR = 5.0  # capture sd above this many times the sensor noise: still moving


def _signed(axis: int, sign: float) -> str:
    return f"{'+' if sign >= 0 else '-'}{AXES[axis]}"


def elevations_deg(ref_g: np.ndarray) -> np.ndarray:
    """Elevation of each sensor axis above the horizontal, degrees: asin(f_i/|f|)."""
    f = np.asarray(ref_g, float)
    return np.degrees(np.arcsin(np.clip(f / np.linalg.norm(f), -1.0, 1.0)))


def instruction_for(ref_g: np.ndarray) -> str:
    """The plain-language placement for a specific-force direction (sensor frame).

    A face position (one axis within 10° of vertical) reads "face +z up"; the
    heading about the vertical is free (gravity does not see it) and is
    suggested only so that the operator repeats it. Oblique positions (cube
    diagonals, tilt fixture) name each axis' elevation.
    """
    el = elevations_deg(ref_g)
    main = int(np.argmax(np.abs(el)))
    if abs(el[main]) >= FACE_UP_DEG:
        side = (main + 1) % 3
        return (f"face {_signed(main, el[main])} up, {AXES[side]} towards the door "
                f"(any heading works: gravity does not see it)")
    parts = ", ".join(f"{AXES[i]} {el[i]:+.0f}°" for i in range(3))
    return (f"oblique: rest the sensor so that its axes rise above the horizontal by {parts} "
            f"(most upward: {_signed(main, el[main])})")


def sketch_for(ref_g: np.ndarray) -> str:
    """A small ASCII side view: the upward sensor axis over the bench."""
    el = elevations_deg(ref_g)
    main = int(np.argmax(np.abs(el)))
    up = _signed(main, el[main])
    side = AXES[(main + 1) % 3]
    tilt = "" if abs(el[main]) >= FACE_UP_DEG else f" (tilted: {up} {el[main]:+.0f}° up)"
    return "\n".join([
        f"      ^ {up} up{tilt}",
        "      |",
        "   +-----+",
        f"   | DUT |--> {side} towards the door",
        "   +-----+",
        "  =========  bench / fixture",
    ])


@dataclass(frozen=True)
class PlacementCheck:
    """Outcome of :func:`check_placement`; ``reason`` is what the operator reads when not ok."""

    ok: bool
    angle_deg: float  # between the measured and the asked direction
    static: bool
    reason: str = ""


def check_placement(mean_g: np.ndarray, sd_g: np.ndarray, ref_g: np.ndarray, noise_g: float,
                    *, max_angle_deg: float = MAX_ANGLE_DEG,
                    static_factor: float = STATIC_FACTOR) -> PlacementCheck:
    """Is the sensor static and roughly where asked?

    Static: every axis' capture sd below ``static_factor`` × ``noise_g`` (the
    sensor's own noise per sample, g). Where asked: :func:`check_pose` (a hand
    placement is good to a few degrees; the fit carries that as ``ref_tol_deg``,
    docs/fit-honesty.md — this check only catches a wrong face).
    """
    sd_max = float(np.max(np.asarray(sd_g, float)))
    if sd_max > static_factor * noise_g:
        return PlacementCheck(False, direction_error_deg(mean_g, ref_g), False, (
            f"the sensor is moving (sd {sd_max * 1e3:.2f} mg against {noise_g * 1e3:.3f} mg "
            f"noise): let it rest, then confirm again"))
    return check_pose(mean_g, ref_g, max_angle_deg=max_angle_deg)


def direction_error_deg(mean_g: np.ndarray, ref_g: np.ndarray) -> float:
    """Angle between the measured specific force and the reference direction, degrees."""
    m = np.asarray(mean_g, float)
    r = np.asarray(ref_g, float)
    cos = float(np.dot(m, r) / (np.linalg.norm(m) * np.linalg.norm(r)))
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def check_pose(mean_g: np.ndarray, ref_g: np.ndarray, *,
               max_angle_deg: float = MAX_ANGLE_DEG) -> PlacementCheck:
    """Does a static capture read gravity from the direction its pose claims?

    The one pose check, of a hand placement (:func:`check_placement`) and of every
    capture the engine stores (a table that silently stopped elsewhere). An
    uncalibrated sensor's direction is off by its zero-g offset and misalignment
    (a few degrees for an ADXL355-class part: 75 mg over temperature is 4.3°), far
    inside ``max_angle_deg``; a wrong face or pose is 45° or more away on the
    shipped schedules. ``reason`` says which axis is where, for the operator.
    """
    angle_deg = direction_error_deg(mean_g, ref_g)
    if angle_deg < max_angle_deg:
        return PlacementCheck(True, angle_deg, True)
    el_asked, el_seen = elevations_deg(np.asarray(ref_g, float)), elevations_deg(mean_g)
    main = int(np.argmax(np.abs(el_asked)))
    asked = "up" if el_asked[main] > 0 else "down"
    seen = "up" if el_seen[main] > 30 else "down" if el_seen[main] < -30 else "sideways"
    seen_main = int(np.argmax(np.abs(el_seen)))
    if seen != asked:
        hint = (f"{AXES[main]} looks {seen}, not {asked} "
                f"({_signed(seen_main, el_seen[seen_main])} is up now): turn the cube")
    else:
        hint = f"{AXES[main]} is {asked} but tilted: seat the fixture flat"
    return PlacementCheck(False, angle_deg, True,
                          f"{hint} ({angle_deg:.0f}° from the asked direction, "
                          f"limit {max_angle_deg:.0f}°)")


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

    def publish(self, ref_g: np.ndarray, reason: str | None = None) -> dict[str, Any] | None:
        """Ask for ``ref_g`` (again, with ``reason``); keeps an identical open request as is."""
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
            row.instruction = instruction_for(r)
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
    return replace(devices, turntable=table,
                   angles_for=lambda ref: tuple(angles_for_reference(np.asarray(ref), 3)))


def hand_placed_calibrate(calibrate: Callable[[dict[str, list[float]], dict[str, Any]],
                                              dict[str, Any]] | None = None,
                          tol_deg: float | None = None
                          ) -> Callable[[dict[str, list[float]], dict[str, Any]], dict[str, Any]]:
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

    def run(columns: dict[str, list[float]], provenance: dict[str, Any]) -> dict[str, Any]:
        n = len(columns["t_s"])
        with_tol = {**columns, REF_TOL_COLUMN: [tol] * n}
        return inner(with_tol, {**provenance, REF_TOL_COLUMN: tol, "placement": "manual"})

    return run
