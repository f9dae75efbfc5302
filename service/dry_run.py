"""Dry run at the door: can this campaign, on this rig, ever produce a calibration?

One function, :func:`check_campaign`, decides it without hardware, for
``POST /api/v1/campaigns``, ``POST /api/v1/schedules``, the scheduler and
``soakcal campaign plan``. It refuses, naming the field:

* a position schedule that cannot identify the 12-parameter SFEM (seed paper,
  Eq. 1–3) in the mode the rig gives. A rig with a turntable knows the gravity
  direction of every position, so its recordings are fitted in *reference* mode
  (``calibration.thermal``: ``mode = "reference" if recording.has_reference``);
  the check is the Jacobian rank of ``calibration.schedules.identifiability``
  (e.g. ``sphere1``: 3 equations for 12 unknowns);
* a setpoint (or the end-of-campaign ``safe_c``) outside the chamber's range
  (``chamber.range_c``, else the controller's register map range);
* a ramp faster than the chamber can follow (``chamber.max_rate_c_per_min``;
  the built-in ``sim`` chamber's physics limit is 5 °C/min);
* a ramp the chamber cannot command (:mod:`drivers.ramp_rule`, the drivers' own rule):
  on a chamber without a static ramp (a map listing ``ramp_c_per_min`` under
  ``absent_roles``, an ESPEC) only 0 (step) or a rate at or above its own; 0 on a
  controller whose map does not say its ramp register's 0 means "no ramp"; and
  ``method: "ramp"`` on a chamber that cannot ramp;
* a step campaign (``ramp_c_per_min`` 0, or any rate on a chamber without a ramp) on a
  rig whose chamber's own rate is unknown: its duration cannot be predicted;
* a position schedule a 1-axis stage with a hand axis cannot reach (the motor's range
  and the indexer's steps, :func:`hand_axis_issue`), which would fail at the start.

and it predicts the campaign's duration in rig time (:func:`predicted_duration_s`;
:func:`prediction` is the form a campaign row stores at creation, so that reading a
campaign never plans it again).

The prediction interprets the campaign's own plan (:func:`dry_run` below);
the checks stay here, in one place.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.campaign_plan import (
    Acquire,
    Home,
    Move,
    Msg,
    Save,
    SetChamber,
    Settle,
    WaitStable,
    campaign_plan,
    interpret,
)
from calibration.campaign_spec import CampaignSpec
from calibration.ramp_plan import (
    RampPrediction,
    describe_prediction,
    predict_ramp,
    travel_move_s,
)
from calibration.thermal_plant import AMBIENT_C
from drivers.ramp_rule import (
    RampControl,
    moving_rate_c_per_min,
    ramp_method_refusal,
    ramp_refusal,
)

# A rig with a turntable commands every gravity direction: reference-mode fits.
RIG_FIT_MODE = "reference"
# Table moves are predicted from the table's own travel in the campaign's position order
# (``dry_run(move_s=None)``: slowest axis on the trapezoidal profile,
# plus the in-position poll), so a travel order's saving shows in the prediction.
# The predictive stability policy ends a soak at ~3/4 of the nominal soak on average
# (service/engine/progress.py uses the same factor for its ETA).
PREDICTIVE_SOAK_FRACTION = 0.75
# The largest campaign the door plans. Planning a step orders its positions for least
# table travel (a 2-opt tour, its cost growing faster than n² per step), so a schedule is
# refused before it is built or planned, naming the limit: ``sphere5000`` took 53 s and
# 3.1 GB, and a few such requests would exhaust the host. 64 positions per step (the
# seed's Table 4 goes up to 64 below its 1296-point reference set; ~15 min of moves,
# settles and acquisitions) and 2,400 positions over the campaign (~10 h) leave room for
# every real protocol: the seed's Table 1 is 24 positions × 11 steps = 264. Planned on
# the shared 2-core machine: 64 × 16 steps 0.4 s, where 100 × 11 took 10 s
# (benchmarks/bench_plan_bound.py).
MAX_POSITIONS = 64
MAX_CAMPAIGN_POSITIONS = 2400
# The built-in simulated chamber's physics limit (simulators/chamber_sim.py).
SIM_MAX_RATE_C_PER_MIN = 5.0


@dataclass(frozen=True)
class PlanIssue:
    """One refused field: where (a 422 ``loc`` tail), why, and the value given."""

    loc: tuple[str | int, ...]
    msg: str
    value: Any


@dataclass(frozen=True)
class PlanCheck:
    """The dry run's verdict: no issues means the campaign can produce a calibration."""

    issues: list[PlanIssue] = field(default_factory=list)
    predicted_duration_s: float | None = None
    n_steps: int = 0
    n_positions: int | None = None
    mode: str = RIG_FIT_MODE
    detail: str | None = None  # a ramp campaign's legs and holds (calibration.ramp_plan)
    # The stored form of the prediction (:func:`prediction`); None when the check refused.
    prediction: dict[str, Any] | None = None

    @property
    def ok(self) -> bool:
        return not self.issues

    def summary(self) -> str:
        """One line for people: steps × positions, mode, predicted duration."""
        dur = self.predicted_duration_s
        if self.detail is not None:
            return f"{self.n_positions} positions per sweep, {self.mode} mode, {self.detail}"
        return (f"{self.n_steps} steps × {self.n_positions} positions, {self.mode} mode, "
                f"predicted duration {dur:.0f} s ({dur / 3600.0:.1f} h of rig time)")


def check_campaign(spec: CampaignSpec, rig: dict[str, Any] | None,
                   rig_name: str | None = None) -> PlanCheck:
    """Every door check of ``spec`` on ``rig`` (a rig row as a dict; None: unknown rig)."""
    if rig is None:
        return PlanCheck([PlanIssue(("rig",), f"unknown rig {rig_name!r}", rig_name)])
    issues: list[PlanIssue] = []
    lo_c, hi_c = chamber_range_c(rig)
    name = rig.get("name")
    for i, setpoint_c in enumerate(spec.setpoints_c):
        if not lo_c <= setpoint_c <= hi_c:
            issues.append(PlanIssue(
                ("setpoints_c", i),
                f"setpoint {setpoint_c:g} °C is outside the chamber range of rig {name!r}, "
                f"[{lo_c:g}, {hi_c:g}] °C", setpoint_c))
    if spec.safe_c is not None and not lo_c <= spec.safe_c <= hi_c:
        issues.append(PlanIssue(
            ("safe_c",), f"safe temperature {spec.safe_c:g} °C is outside the chamber range "
            f"of rig {name!r}, [{lo_c:g}, {hi_c:g}] °C", spec.safe_c))
    ctrl = chamber_ramp_control(rig)
    step_rate, why_ramp = _ramp_verdict(spec, ctrl, name)
    if why_ramp is not None:
        issues.append(why_ramp)
    max_rate = chamber_max_rate_c_per_min(rig)
    if ctrl.controlled and max_rate is not None and spec.ramp_c_per_min > max_rate:
        issues.append(PlanIssue(
            ("ramp_c_per_min",), f"ramp {spec.ramp_c_per_min:g} °C/min is faster than the "
            f"chamber of rig {name!r} can follow ({max_rate:g} °C/min)", spec.ramp_c_per_min))
    n_positions, why = schedule_verdict(spec.positions, RIG_FIT_MODE)
    if why is None and n_positions is not None and (
            n_positions * len(spec.setpoints_c) > MAX_CAMPAIGN_POSITIONS):
        n_positions, why = None, (
            f"{len(spec.setpoints_c)} setpoints × {n_positions} positions is "
            f"{len(spec.setpoints_c) * n_positions} positions, more than the "
            f"{MAX_CAMPAIGN_POSITIONS} a campaign may have; use fewer setpoints or a "
            "smaller position schedule")
    if why is not None:
        issues.append(PlanIssue(("positions",), why, spec.positions))
    elif n_positions is not None:
        unreachable = hand_axis_issue(spec.positions, rig)
        if unreachable is not None:
            issues.append(unreachable)
            n_positions = None
    if n_positions is not None and spec.method == "ramp":
        if not ctrl.controlled:  # no ramp to predict: the method is refused above
            return PlanCheck(issues, None, 0, n_positions)
        pred = predicted_ramp(spec)
        return PlanCheck(issues, pred.duration_s, pred.n_sweeps, n_positions,
                         detail=describe_prediction(pred, spec.ramp_c_per_min),
                         prediction=ramp_prediction(pred))
    predicted = (None if n_positions is None or (step_rate is None and why_ramp is not None)
                 else prediction(spec, step_rate))
    duration = None if predicted is None else predicted["duration_s"]
    return PlanCheck(issues, duration, len(spec.setpoints_c), n_positions,
                     prediction=predicted)


def hand_axis_issue(positions: str, rig: dict[str, Any]) -> PlanIssue | None:
    """A schedule a 1-axis stage with a hand axis cannot reach (docs/manual-fixtures.md,
    "One motorised axis, one by hand"): its first unreachable position and why
    (:func:`drivers.geometry.hand_axis_unreachable`, the engine's own geometry), else None.

    The motor's range is the turntable map's ``range_deg``; a map that does not load is
    the rig validation's to name, and the engine's geometry refuses at start."""
    from drivers.geometry import hand_axis_unreachable
    from drivers.registermaps import MapError, load_turntable_map
    from service.engine.rigs import hand_axis_steps, has_hand_axis
    from service.engine.spec import schedule_refs

    table = rig.get("turntable") or {}
    if not has_hand_axis(table):
        return None
    try:
        motor_range_deg = load_turntable_map(str(table.get("map", "soakcal-table"))).range_deg
        steps = hand_axis_steps(table)
        refs = schedule_refs(positions)
    except (MapError, OSError, ValueError, TypeError):
        return None
    bad = hand_axis_unreachable(refs, steps, motor_range_deg)
    if not bad:
        return None
    first, reason = bad[0]
    ref = ", ".join(f"{v:+.3f}" for v in refs[first] / np.linalg.norm(refs[first]))
    more = f" (and {len(bad) - 1} more of its {len(refs)} positions)" if len(bad) > 1 else ""
    fix = ("add the indexer steps they need to turntable.hand_axis.steps_deg, or use a "
           "schedule whose positions the stage reaches (e.g. six with steps of 90°)")
    return PlanIssue(("positions",), (
        f"schedule {positions!r}: rig {rig.get('name')!r} (one motorised axis, the second "
        f"by hand) cannot reach position {first} (ref ({ref}) g){more}: {reason}; {fix}"),
        positions)


def chamber_range_c(rig: dict[str, Any]) -> tuple[float, float]:
    """``chamber.range_c``, else the range of the controller's register map, else unbounded."""
    chamber = rig.get("chamber") or {}
    bounds = chamber.get("range_c")
    if isinstance(bounds, list | tuple) and len(bounds) == 2:
        return (float(bounds[0]), float(bounds[1]))
    if chamber.get("driver", "sim") == "modbus":
        from drivers.registermaps import CHAMBER_MAPS

        regmap = CHAMBER_MAPS.get(str(chamber.get("map", "eurotherm3216")))
        if regmap is not None:
            return regmap.range_c
    return (-math.inf, math.inf)


def chamber_ramp_control(rig: dict[str, Any]) -> RampControl:
    """What the rig's chamber does with a commanded ramp (:mod:`drivers.ramp_rule`), as its
    driver will: an ESPEC, or the register map of a ``modbus`` chamber or of the ``sim``
    twin (which serves the map ``eurotherm-3216``)."""
    chamber = rig.get("chamber") or {}
    rate = chamber_max_rate_c_per_min(rig)
    if chamber.get("driver", "sim") == "espec":
        from drivers.espec_chamber import espec_ramp_control

        return espec_ramp_control(rate)
    from drivers.ramp_rule import map_ramp_control
    from drivers.registermaps import MapError, load_chamber_map

    map_name = str(chamber.get("map", "eurotherm3216"))
    try:
        regmap = load_chamber_map(map_name)
    except (MapError, OSError, ValueError):
        # The rig's own validation names a bad map; here: a ramp register is assumed and
        # the driver refuses at the wire what the map cannot do.
        return RampControl(f"map {map_name}", True, "could not be loaded to say more", rate)
    return map_ramp_control(regmap, rate)


def _ramp_verdict(spec: CampaignSpec, ctrl: RampControl,
                  rig_name: Any) -> tuple[float | None, PlanIssue | None]:
    """(the rate a soak campaign's steps are predicted at, °C/min, None for the commanded
    one; the refusal, if any). A chamber that steps (no ramp, or 0 commanded) moves at its
    own rate: known, or the duration cannot be predicted and the campaign is refused."""
    rate = spec.ramp_c_per_min
    if spec.method == "ramp":
        why = ramp_method_refusal(ctrl)
        return None, (None if why is None else PlanIssue(("method",), why, spec.method))
    why = ramp_refusal(ctrl, rate)
    if why is not None:
        return None, PlanIssue(("ramp_c_per_min",), why, rate)
    if ctrl.controlled and rate > 0:
        return None, None  # predicted at the commanded rate
    own = moving_rate_c_per_min(ctrl, rate)
    if own is None:
        return None, PlanIssue(
            ("ramp_c_per_min",),
            f"ramp_c_per_min {rate:g} on rig {rig_name!r}: its chamber ({ctrl.controller}) "
            "steps to each setpoint at its own rate, which the rig does not state, so the "
            f"campaign's duration cannot be predicted; set {ctrl.rate_key} to the "
            "chamber's fastest rate (its data sheet)", rate)
    return own, None


def chamber_max_rate_c_per_min(rig: dict[str, Any]) -> float | None:
    """The fastest ramp the chamber follows: configured, or the sim's physics; None: unknown."""
    chamber = rig.get("chamber") or {}
    rate = chamber.get("max_rate_c_per_min")
    if isinstance(rate, int | float) and not isinstance(rate, bool) and rate > 0:
        return float(rate)
    if chamber.get("driver", "sim") == "sim":
        return SIM_MAX_RATE_C_PER_MIN
    return None


@functools.lru_cache(maxsize=128)
def schedule_verdict(name: str, mode: str) -> tuple[int | None, str | None]:
    """(number of positions, None) when ``name`` identifies the SFEM in ``mode``, else why not."""
    from calibration.schedules import get_schedule, identifiability

    try:
        # Counted before anything is built: sphere<N> has N positions.
        n_total = sum(int(part[6:]) if part.startswith("sphere") and part[6:].isdigit()
                      else len(get_schedule(part)) for part in name.strip().lower().split("+"))
        if n_total > MAX_POSITIONS:
            return None, (f"position schedule {name!r} has {n_total} positions, more than the "
                          f"{MAX_POSITIONS} per step the door plans (a night has room for far "
                          "fewer); use a smaller schedule such as table1 or sphere48")
        refs = get_schedule(name)
    except (ValueError, KeyError):
        return None, (f"unknown position schedule {name!r}; expected table1, six, cube14, "
                      "sphere<N> or a sum such as table1+cube14")
    ident = identifiability(refs, mode)
    if not ident.ok:
        return len(refs), (
            f"position schedule {name!r} ({len(refs)} position(s)) cannot identify the "
            f"12-parameter model in {mode} mode (the mode of a rig with a turntable): "
            f"rank {ident.rank} of {ident.n_params}, undetermined {', '.join(ident.undetermined)}")
    return len(refs), None


def predicted_duration_s(spec: CampaignSpec, step_rate_c_per_min: float | None = None) -> float:
    """Rig-time estimate of the whole campaign, s (:func:`prediction`'s ``duration_s``);
    ``ValueError`` naming why when it cannot be predicted."""
    predicted = prediction(spec, step_rate_c_per_min)
    if predicted["duration_s"] is None:
        raise ValueError(predicted["why"])
    return float(predicted["duration_s"])


def prediction(spec: CampaignSpec, step_rate_c_per_min: float | None = None) -> dict[str, Any]:
    """The dry run of ``spec`` as a campaign row stores it (JSON): ``duration_s``,
    ``ramp_s``, ``soak_s``, ``positions_s`` (rig time, s; a sped-up sim rig: divide by its
    speed), ``n_steps``, ``n_positions`` and ``n_saves``.

    The campaign's own plan interpreted without hardware (:func:`dry_run`):
    ramps at ``ramp_c_per_min`` from ambient through every setpoint, one soak per step
    (the nominal soak; ~3/4 of it under the predictive policy), and per position a move
    (the table's travel from the pose before, in the spec's ``position_order``), the
    settle and one acquisition (``samples / odr_hz``) for all its sensors: a campaign's
    sensors are read at once, so eight take the time of one.

    ``step_rate_c_per_min``: the chamber's own rate, for a chamber that steps (no static
    ramp, or ``ramp_c_per_min`` 0); the steps are then predicted at it. A step campaign
    without it is not predicted: ``duration_s`` None and ``why``.
    """
    if spec.method == "ramp":
        return ramp_prediction(predicted_ramp(spec))
    if step_rate_c_per_min is None and not spec.ramp_c_per_min > 0:
        return {"duration_s": None, "why": "ramp_c_per_min 0 (step): the chamber moves at "
                "its own rate, which is not known here (the rig's chamber.max_rate_c_per_min)"}
    soak_s = spec.soak_min * 60.0
    if spec.stability == "predictive":
        soak_s *= PREDICTIVE_SOAK_FRACTION
    plan = dry_run(spec, soak_s=soak_s, move_s=None, start_c=AMBIENT_C,
                   step_rate_c_per_min=step_rate_c_per_min)
    return {"duration_s": plan.duration_s, "ramp_s": plan.ramp_s, "soak_s": plan.soak_s,
            "positions_s": plan.positions_s, "n_steps": plan.n_steps,
            "n_positions": plan.n_positions, "n_saves": plan.n_saves}


def predicted_ramp(spec: CampaignSpec, start_c: float = AMBIENT_C) -> RampPrediction:
    """A ramp campaign's prediction (:func:`calibration.ramp_plan.predict_ramp`): its plan on
    a first-order die of the prior lag, moves from the table's travel, back to ``safe_c``."""
    from drivers.geometry import angles_for_references
    from service.engine.spec import schedule_refs

    refs = schedule_refs(spec.positions)
    poses = angles_for_references(refs)
    move = travel_move_s(refs, poses, *_table_limits(), in_position_s=IN_POSITION_S)
    end_c = AMBIENT_C if spec.safe_c is None else spec.safe_c
    return predict_ramp(spec, refs, start_c=start_c, end_c=end_c, move_s=move,
                        angles_deg=poses)


def ramp_prediction(pred: RampPrediction) -> dict[str, Any]:
    """A ramp's prediction as a campaign row stores it (JSON): ``duration_s`` (rig time, s),
    ``method``, ``legs`` (target_c, ramp_s, hold_s each), ``n_sweeps``, ``n_saves`` and the
    die lag it assumed (``die_tau_s``)."""
    return {"duration_s": pred.duration_s, "method": "ramp",
            "legs": [dict(leg) for leg in pred.legs], "n_sweeps": pred.n_sweeps,
            "n_saves": pred.n_saves, "die_tau_s": pred.die_tau_s}


# --- the dry-run interpreter of the campaign plan (calibration.campaign_plan) ---------------
DEFAULT_MOVE_S = 12.0  # table slew + in-position between orientations (seed Table 3 rigs)
# Beyond the slew itself a move waits for in-position: the engine polls the table every
# second (runner.TURNTABLE_POLL_S), so on average ~1 s more than the trapezoid.
IN_POSITION_S = 1.0


@dataclass
class DryRun:
    """What a campaign will do, predicted without hardware."""

    duration_s: float  # predicted campaign time (rig clock), s
    n_steps: int  # setpoints that will be visited
    n_positions: int  # orientations per step
    n_saves: int  # readings the campaign will store
    ramp_s: float  # predicted total ramping, s
    soak_s: float  # predicted total soaking, s
    positions_s: float  # predicted total moving + settling + acquiring, s
    steps: list[dict[str, float]] = field(default_factory=list)  # per step: setpoint_c, *_s


def dry_run(spec: Any, *, refs: np.ndarray | None = None, soak_s: float | None = None,
            move_s: float | None = DEFAULT_MOVE_S, start_c: float = AMBIENT_C,
            done: Iterable[tuple[int, int]] = (), sensors: Sequence[str] | None = None,
            angles_deg: np.ndarray | None = None,
            step_rate_c_per_min: float | None = None) -> DryRun:
    """Interpret the campaign plan without hardware: predicted duration and counts.

    ``spec`` is a campaign's JSON spec (the ``POST /campaigns`` body as a dict), a
    validated :class:`CampaignSpec` or the engine's ``RunSpec``; ``ValueError`` when
    it cannot be parsed.
    ``refs`` defaults to the spec's named schedule; ``soak_s`` to the nominal
    soak (``soak_min`` × 60: the predictive policy usually ends earlier, so
    the prediction is an upper estimate); ``move_s`` is the time per table
    move, or ``None`` for the table's own travel: each move's slowest axis on
    the trapezoidal profile of :mod:`calibration.position_order` from the pose
    before (home at the start), plus :data:`IN_POSITION_S`, so the position
    order's saving is in the figure; ``start_c`` the chamber's temperature at
    the start. Ramps are predicted at the commanded rate, acquisitions at
    ``n_samples / odr_hz`` once per position however many sensors (they are read
    concurrently; ``sensors`` default the spec's serials). Pass ``done`` (stored (step,
    position) pairs) to predict the rest of a resumed campaign. ``step_rate_c_per_min``:
    the chamber's own rate when it steps (no static ramp, or ``ramp_c_per_min`` 0): the
    ramps are predicted at it; a step without it is a ``ValueError`` (never a made-up rate).
    """
    from calibration.position_order import axis_move_s
    from drivers.geometry import angles_for_references
    from service.engine.spec import parse_spec, run_spec, schedule_refs

    if isinstance(spec, dict):
        spec = parse_spec(spec)
    elif isinstance(spec, CampaignSpec):
        spec = run_spec(spec)
    if spec.method == "ramp":  # never a soak's figure for a ramp
        raise ValueError("a ramp campaign is predicted by predicted_ramp "
                         "(calibration.ramp_plan.predict_ramp), not by the soak plan")
    if refs is None:
        refs = schedule_refs(spec.positions)
    if soak_s is None:
        soak_s = float(spec.stability.soak_s)
    if sensors is None:
        sensors = list(spec.sensors)
    refs = np.asarray(refs, float)
    poses = angles_for_references(refs) if angles_deg is None else np.asarray(angles_deg, float)
    pose_of = {tuple(np.round(r, 12)): poses[i] for i, r in enumerate(refs)}
    here = {"deg": np.zeros(poses.shape[1])}

    def travel_move_s(ref_g: tuple[float, float, float]) -> float:
        to = pose_of[tuple(np.round(np.asarray(ref_g, float), 12))]
        dt_s = float(axis_move_s(to - here["deg"], *_table_limits()).max())
        here["deg"] = to
        return dt_s + IN_POSITION_S

    state = {"c": float(start_c)}
    odr_hz = float(spec.odr_hz)
    out = DryRun(0.0, 0, int(np.asarray(refs).shape[0]), 0, 0.0, 0.0, 0.0)

    def handle(msg: Msg) -> Any:
        if isinstance(msg, SetChamber):
            rate = msg.ramp_c_per_min if step_rate_c_per_min is None else step_rate_c_per_min
            if not rate > 0:
                raise ValueError("ramp_c_per_min 0 (step): the chamber moves at its own "
                                 "rate; give it (step_rate_c_per_min) to predict the ramps")
            dt_s = abs(msg.setpoint_c - state["c"]) / rate * 60.0
            state["c"] = msg.setpoint_c
            out.ramp_s += dt_s
            out.n_steps += 1
            out.steps.append({"setpoint_c": msg.setpoint_c, "ramp_s": dt_s, "soak_s": 0.0,
                              "positions_s": 0.0})
        elif isinstance(msg, Home):  # the table goes home during the ramp: no time of its own
            here["deg"] = np.zeros(poses.shape[1])
        elif isinstance(msg, WaitStable):
            out.soak_s += soak_s
            out.steps[-1]["soak_s"] = soak_s
        elif isinstance(msg, Move | Settle | Acquire):
            if isinstance(msg, Move):
                dt_s = travel_move_s(msg.ref_g) if move_s is None else move_s
            else:
                dt_s = msg.settle_s if isinstance(msg, Settle) else msg.n_samples / odr_hz
            out.positions_s += dt_s
            out.steps[-1]["positions_s"] += dt_s
        elif isinstance(msg, Save):
            out.n_saves += 1
        return None

    interpret(campaign_plan(spec, refs, done, sensors, poses), handle)
    out.duration_s = out.ramp_s + out.soak_s + out.positions_s
    return out


def _table_limits() -> tuple[float, float]:
    from calibration.position_order import DEFAULT_ACCEL_DEG_PER_S2, DEFAULT_SLEW_DEG_PER_S

    return DEFAULT_SLEW_DEG_PER_S, DEFAULT_ACCEL_DEG_PER_S2
