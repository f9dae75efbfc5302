"""Offline ramp campaign: the engine's ramp plan interpreted with the twin's physics.

:func:`simulate_ramp_campaign` runs :func:`calibration.ramp_plan.ramp_plan` -- the same
generator the engine runs -- on :class:`calibration.ramp_plan.RampPlant`: the chamber's
working setpoint at the commanded rate, the air first-order behind it, and one die per
sensor first-order behind the air with its *own* time constant (several dies with
different lags: the hold at a turnaround ends on the slowest). Each capture is a reading
of every sensor at once, taken at mid-capture with each die's rate over the capture
(``temperature_rate``) and each die's own last excursion (``thermal_hysteresis``: +1
heating, −1 cooling; −1 before the first, the rig having cooled to its start), drawn from
the sampling distribution of the mean of n samples (:func:`simulators.truth.averaged_readings`).

The recordings have what the engine stores: ``step`` (the sweep), ``position``,
``setpoint_c`` (the leg's target), ``t_s``, ``chamber_c`` (air + PV noise), ``sensor_c``
(each die through its channel: offset, noise, optional per-row noise and quantum), the
references, means, sds and n. Imports calibration and simulators only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration import ramp_plan as rp
from calibration.campaign_plan import (
    Acquire,
    Move,
    ReadChamber,
    Save,
    SetChamber,
    Settle,
    interpret,
)
from calibration.recording import Recording
from calibration.schedules import table1
from calibration.thermal_plant import AMBIENT_C
from simulators.ramp_sim import DIRECTION_RATE_C_PER_S, _direction
from simulators.truth import Context, SensorTruth, averaged_readings


@dataclass(frozen=True)
class RampCampaignRig:
    """The rig's timing and noise (the wire twin's figures: air τ 60 s, 12 s moves)."""

    air_tau_s: float = 60.0
    move_s: float = 12.0
    pv_noise_c: float = 0.02
    start_c: float = AMBIENT_C
    end_c: float = AMBIENT_C
    dt_s: float = 2.0


@dataclass(frozen=True)
class RampCampaignSpec:
    """The campaign spec keys the ramp plan reads (a ``CampaignSpec`` works too)."""

    setpoints_c: Sequence[float] = (-40.0, 60.0)
    samples_per_position: int = 200
    ramp_c_per_min: float = 3.0
    settle_s: float = 5.0
    range_g: float = 2.0
    odr_hz: float = 62.5
    position_order: str = "table"
    position_order_seed: int | None = None
    tol_c: float = rp.DEFAULT_ARRIVED_C
    soak_min: float = 60.0
    max_soak_min: float | None = None


@dataclass
class RampCampaign:
    """One simulated ramp campaign: a recording per sensor and the rig's timeline."""

    recordings: list[Recording]
    die_c: np.ndarray  # (rows, sensors) true die temperature at mid-capture
    air_c: np.ndarray  # (rows,)
    duration_s: float
    legs: list[dict[str, float]] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)


def simulate_ramp_campaign(
    truths: Sequence[SensorTruth],
    die_tau_s: Sequence[float],
    spec: Any = RampCampaignSpec(),  # noqa: B008 (frozen)
    rig: RampCampaignRig = RampCampaignRig(),  # noqa: B008 (frozen)
    seed: int = 0,
    *,
    schedule: np.ndarray | None = None,
    temp_row_noise_c: float = 0.0,
    temp_lsb_c: float = 0.0,
) -> RampCampaign:
    """The ramp campaign of ``truths`` (one die lag each) on one rig (module docstring)."""
    if len(truths) != len(die_tau_s):
        raise ValueError("one die_tau_s per sensor")
    refs = table1() if schedule is None else np.asarray(schedule, float)
    plant = rp.RampPlant(float(rig.start_c), [float(t) for t in die_tau_s],
                         air_tau_s=rig.air_tau_s, dt_s=rig.dt_s)
    serials = [f"S{i}" for i in range(len(truths))]
    odr = float(spec.odr_hz)
    rows: dict[str, list[Any]] = {k: [] for k in (
        "t_s", "air", "die", "rate", "step", "position", "setpoint_c", "ref")}
    legs: list[dict[str, float]] = []
    pending: dict[str, Any] = {}

    def handle(msg: Any) -> Any:
        if isinstance(msg, SetChamber):
            plant.setpoint_c, plant.rate_c_per_min = msg.setpoint_c, msg.ramp_c_per_min
            legs.append({"target_c": msg.setpoint_c, "start_s": plant.t_s})
            return None
        if isinstance(msg, ReadChamber):
            return plant.status()
        if isinstance(msg, Move):
            plant.advance(rig.move_s)
        elif isinstance(msg, Settle):
            plant.advance(msg.settle_s)
        elif isinstance(msg, Acquire):
            capture_s = msg.n_samples / odr
            before = plant.die_c.copy()
            plant.advance(capture_s / 2.0)
            pending.update(t_s=plant.t_s, air=plant.air_c, die=plant.die_c.copy())
            plant.advance(capture_s / 2.0)
            pending["rate"] = (plant.die_c - before) / capture_s
            return {s: rp._Reading(float(d)) for s, d in zip(serials, pending["die"],
                                                             strict=True)}
        elif isinstance(msg, Save):
            for key in ("t_s", "air", "die", "rate"):
                rows[key].append(pending[key])
            rows["step"].append(msg.step)
            rows["position"].append(msg.position)
            rows["setpoint_c"].append(msg.setpoint_c)
            rows["ref"].append(msg.ref_g)
        return None

    interpret(rp.ramp_plan(spec, refs, end_c=rig.end_c, sensors=serials), handle)

    rng = np.random.default_rng(seed)
    N = len(rows["t_s"])
    t = np.asarray(rows["t_s"], float)
    air = np.asarray(rows["air"], float)
    die = np.asarray(rows["die"], float).reshape(N, len(truths))
    rate = np.asarray(rows["rate"], float).reshape(N, len(truths))
    ref = np.asarray(rows["ref"], float).reshape(N, 3)
    n = int(spec.samples_per_position)
    recordings = []
    for i, truth in enumerate(truths):
        moving = np.where(np.abs(rate[:, i]) > DIRECTION_RATE_C_PER_S, np.sign(rate[:, i]), 0.0)
        ctx = Context(t_s=t, die_c=die[:, i], air_c=air, die_rate_c_per_s=rate[:, i],
                      ref_g=ref, step=np.asarray(rows["step"], int),
                      direction=_direction(moving, start=-1), session=np.zeros(N, int),
                      n_samples=np.full(N, float(n)), vib_sd_g=np.zeros(N))
        mean, sd, sensor_c = averaged_readings(truth, ctx, rng)
        sensor_c = sensor_c + rng.normal(0.0, temp_row_noise_c, N)
        if temp_lsb_c > 0:
            sensor_c = np.round(sensor_c / temp_lsb_c) * temp_lsb_c
        recordings.append(Recording.from_columns({
            "t_s": t, "step": np.asarray(rows["step"], float),
            "setpoint_c": np.asarray(rows["setpoint_c"], float),
            "chamber_c": air + rng.normal(0.0, rig.pv_noise_c, N), "sensor_c": sensor_c,
            "position": np.asarray(rows["position"], float),
            "ref_x": ref[:, 0], "ref_y": ref[:, 1], "ref_z": ref[:, 2],
            "ax": mean[:, 0], "ay": mean[:, 1], "az": mean[:, 2], "n": np.full(N, float(n)),
            "sd_x": sd[:, 0], "sd_y": sd[:, 1], "sd_z": sd[:, 2]}))
    for j, leg in enumerate(legs):
        leg["end_s"] = legs[j + 1]["start_s"] if j + 1 < len(legs) else plant.t_s
    return RampCampaign(recordings, die, air, plant.t_s, legs)
