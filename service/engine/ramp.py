"""Ramp campaigns in the engine: the ramp plan resumed from the store, and its progress.

The ramp plan (:func:`calibration.ramp_plan.ramp_plan`) runs on the engine's own
verbs: ``SetChamber`` (commands, no waiting), ``ReadChamber``, and the
``measure_position`` stub whose ``Save`` has the setpoint band off (the air is meant to
be away from the setpoint; alarms, the pose and the die checks still apply). What is
a ramp's own is here:

* **resume** (after a restart, or a suspension's rewind): the stored (step, position)
  pairs and the legs already finished, from the stored rows' setpoints in time order and,
  for a turnaround hold, its stored dies (:func:`calibration.ramp_plan.resumed_legs_done`:
  a hold they already end is not held again); the current leg is commanded again
  from wherever the chamber stands;
* **where the last leg goes**: the campaign's ``safe_c``, else the rig's safe setpoint,
  clamped into the chamber's range (as the park);
* **progress**: a ramp has no steps to count. Its ETA is the prediction of
  :func:`calibration.ramp_plan.predict_ramp` from the chamber's temperature when the
  plan (re)starts, less the active time since; ``step`` is the sweep.
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


class RampProgress:
    """The ramp plan of one runner (:class:`service.engine.runner.CampaignRunner`), resumed
    from its store, and the progress fields its ``_publish`` adds."""

    def __init__(self, runner: Any) -> None:
        self.r = runner
        self.predicted_s: float | None = None
        self.predicted_sweeps = 0
        self.active0_s = 0.0
        self.legs_done = 0

    def plan(self, spec: Any, refs: np.ndarray, done: set[tuple[int, int]], *,
             sensors: Any, angles_deg: np.ndarray) -> Any:
        """The ramp plan after what is stored (the runner's plan factory: campaign_plan's
        signature; a fresh prediction at its first publish)."""
        r = self.r
        serials = [str(s) for s in sensors] or ([r.serials[0]] if r.serials else [None])
        cols = store.measurement_columns(r.sf, r.id, serials[0])
        self.end_c = end_c(r.dev, r.spec)
        self.legs_done = 0
        if cols["setpoint_c"]:
            legs = rp.ramp_legs(r.spec.setpoints_c, cols["chamber_c"][0], self.end_c)
            dies = {str(serial): (cols if i == 0 else
                                  store.measurement_columns(r.sf, r.id, serial))["sensor_c"]
                    for i, serial in enumerate(serials)}
            self.legs_done = rp.resumed_legs_done(cols["setpoint_c"], dies, legs, spec,
                                                  len(refs))
        self.done, self.angles_deg, self.n_done0 = done, angles_deg, len(done)
        self.predicted_s = None
        return rp.ramp_plan(spec, refs, end_c=self.end_c, done=done,
                            legs_done=self.legs_done, sensors=sensors, angles_deg=angles_deg)

    def _predict(self, start_c: float) -> None:
        from calibration.position_order import DEFAULT_ACCEL_DEG_PER_S2, DEFAULT_SLEW_DEG_PER_S

        r = self.r
        move = rp.travel_move_s(r.refs, self.angles_deg, DEFAULT_SLEW_DEG_PER_S,
                                DEFAULT_ACCEL_DEG_PER_S2)
        pred = rp.predict_ramp(r.spec, r.refs, start_c=start_c, end_c=self.end_c,
                               move_s=move, angles_deg=self.angles_deg, done=self.done,
                               legs_done=self.legs_done)
        self.predicted_s, self.predicted_sweeps = pred.duration_s, pred.n_sweeps
        self.predicted_saves = pred.n_saves
        self.active0_s = r._active_s()

    def fields(self, status: ChamberStatus, target_c: float) -> dict[str, Any]:
        """Progress of a ramp: method, sweeps, fraction and ETA from the prediction."""
        if self.predicted_s is None:
            self._predict(status.process_c)
        assert self.predicted_s is not None
        eta_s = max(0.0, self.predicted_s - (self.r._active_s() - self.active0_s))
        # captures stored over those stored before this plan and those it predicts
        fraction = self.r.eta.n_done / max(self.n_done0 + self.predicted_saves, 1)
        return {"method": "ramp", "steps": self.predicted_sweeps, "leg_target_c": target_c,
                "fraction": round(min(1.0, fraction), 4), "eta_s": round(eta_s, 1)}
