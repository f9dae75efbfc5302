"""Ramp campaigns in the engine: the ramp plan's verbs and its progress, in one place.

The ramp plan (:func:`calibration.ramp_plan.ramp_plan`) needs three things beyond the
soak's messages, all here: ``ReadChamber`` (the chamber's status; a chamber alarm holds
the campaign as anywhere else, the setpoint band is not armed: the air is meant to be
away from the setpoint), ``CommandChamber`` (setpoint and ramp rate, without waiting
for arrival) and ``RampSave`` (a capture stored without the setpoint-band check: the
runner's ``Save`` with ``band`` False). Moves, settles, captures, the pose and die
checks, pause, abort and the fit are the runner's own.

Resume: the stored (step, position) pairs and the legs already finished (from the
stored rows' setpoints, :func:`calibration.ramp_plan.legs_done_from`); the current leg
is commanded again from wherever the chamber stands. Progress: the prediction of
:func:`calibration.ramp_plan.predict_ramp` at the start; the ETA is that less the
campaign's active time so far.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np

from calibration import ramp_plan as rp
from calibration.thermal_plant import AMBIENT_C
from drivers.protocols import ChamberStatus
from service.engine import store


def end_c(devices: Any, spec: Any) -> float:
    """Where the last leg goes: the campaign's ``safe_c``, else the rig's safe setpoint
    (the map's ``[safe]``), else ambient; inside the chamber's range (as the park)."""
    safe_c = getattr(spec, "safe_c", None)
    if safe_c is None:
        safe_c = float(getattr(devices.chamber, "safe_setpoint_c", AMBIENT_C))
    with contextlib.suppress(Exception):
        lo_c, hi_c = devices.chamber.range_c
        safe_c = min(max(safe_c, lo_c), hi_c)
    return float(safe_c)


class RampSteps:
    """The ramp plan's verbs on one runner (:class:`service.engine.runner.CampaignRunner`)."""

    def __init__(self, runner: Any) -> None:
        self.r = runner
        self.leg: rp.CommandChamber | None = None
        self.predicted_s: float | None = None
        self.active0_s = 0.0
        self.reads = 0
        self.predicted_sweeps = 0

    def plan(self, done: set[tuple[int, int]], angles_deg: np.ndarray) -> Any:
        """The ramp plan, resumed after what is stored."""
        r = self.r
        cols = store.measurement_columns(r.sf, r.id, r.serials[0] if r.serials else None)
        legs_done = 0
        if cols["setpoint_c"]:
            # the legs as the plan builds them (only their targets count here)
            legs = rp.ramp_legs(r.spec.setpoints_c, cols["chamber_c"][0], self.end_c)
            legs_done = rp.legs_done_from(cols["setpoint_c"], legs)
        self.legs_done = legs_done
        self.angles_deg = angles_deg
        return rp.ramp_plan(r.spec, r.refs, end_c=self.end_c, done=done, legs_done=legs_done,
                            sensors=r.serials, angles_deg=angles_deg)

    @property
    def end_c(self) -> float:
        return end_c(self.r.dev, self.r.spec)

    async def read_chamber(self, _msg: rp.ReadChamber) -> ChamberStatus:
        """The chamber's status; a chamber alarm holds the campaign (band not armed).

        Right after a save (no clock time since) the save's own read, already checked for
        alarms, is the status: one Modbus read per capture instead of two."""
        cached = self.r._status_at
        if cached is not None and cached[0] == self.r.clock.now():
            status = cached[1]
        else:
            status = await self.r._chamber_watched(None)
        if self.predicted_s is None:  # the first read: predict from where the chamber is
            self.active0_s = self.r._active_s()
            from calibration.position_order import (
                DEFAULT_ACCEL_DEG_PER_S2,
                DEFAULT_SLEW_DEG_PER_S,
            )

            move = rp.travel_move_s(self.r.refs, self.angles_deg, DEFAULT_SLEW_DEG_PER_S,
                                    DEFAULT_ACCEL_DEG_PER_S2)
            pred = rp.predict_ramp(
                self.r.spec, self.r.refs, start_c=status.process_c, end_c=self.end_c,
                legs_done=self.legs_done, move_s=move, angles_deg=self.angles_deg)
            self.predicted_s, self.predicted_sweeps = pred.duration_s, pred.n_sweeps
        target = self.leg.setpoint_c if self.leg is not None else status.setpoint_c
        # One read per capture: the progress row is written every sweep's worth of reads
        # (each capture's commit writes it too).
        self.r._publish(self.r._progress.get("step", 0), "ramp", 0, status, target,
                        write=self.reads % len(self.r.refs) == 0)
        self.reads += 1
        return status

    async def command_chamber(self, msg: rp.CommandChamber) -> None:
        """Setpoint and rate, the chamber running; no waiting: the plan sweeps meanwhile."""
        r, ch = self.r, self.r.dev.chamber
        self.leg = msg
        store.set_cursor(r.sf, r.id, msg.leg, "ramp", 0)
        r._cursor = (msg.leg, "ramp")
        await r.guard.call("chamber.set_ramp_rate", lambda: ch.set_ramp_rate(msg.ramp_c_per_min))
        await r.guard.call("chamber.set_setpoint", lambda: ch.set_setpoint(msg.setpoint_c))
        await r.guard.call("chamber.run", ch.run)

    def progress(self) -> dict[str, float]:
        """fraction and ETA (s) from the prediction made at the start."""
        if self.predicted_s is None:
            return {}
        done_s = self.r._active_s() - self.active0_s
        eta_s = max(0.0, self.predicted_s - done_s)
        total_s = max(done_s + eta_s, 1e-9)
        return {"method": "ramp", "steps": self.predicted_sweeps,
                "fraction": round(min(1.0, done_s / total_s), 4), "eta_s": round(eta_s, 1),
                "leg": None if self.leg is None else self.leg.leg,
                "leg_target_c": None if self.leg is None else self.leg.setpoint_c}
