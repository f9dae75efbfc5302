"""The campaign as a plan: a generator of small messages, written once, run by many interpreters.

The thermal-soak protocol of the seed paper (ramp → soak → every scheduled
orientation at each setpoint → fit; seed Sec. 3, Table 1, Eq. 1's twelve
parameters identified from the collected readings) is this one generator,
:func:`campaign_plan`. It says *what* to do; an interpreter decides *how*:

* the engine (:class:`service.engine.runner.CampaignRunner`) drives devices,
  commits each ``Save`` with the cursor in one transaction, applies pause and
  abort at ``Checkpoint``, and feeds progress/ETA subscribers;
* the offline simulator (:func:`simulators.campaign_sim.simulate_campaign`)
  integrates the chamber and die physics for each message;
* :func:`dry_run` predicts the duration and counts without any hardware.

The model is bluesky's RunEngine: a plan yields messages, the interpreter
executes each and ``send``\\ s the result back (``Acquire`` returns the
acquisition the following ``Save`` stores). Resuming is a replay of the same
plan that skips what is already stored: pass the stored (step, position)
pairs as ``done``; a step with every position stored is skipped entirely, a
step with some stored is re-ramped (idempotent) and re-soaked as ``resumed``.
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Configure:
    """Configure the accelerometer (range ±g, output data rate Hz)."""

    range_g: float
    odr_hz: float


@dataclass(frozen=True)
class SetChamber:
    """Command the chamber to ``setpoint_c`` at ``ramp_c_per_min``; done when it got there."""

    step: int
    setpoint_c: float
    ramp_c_per_min: float


@dataclass(frozen=True)
class WaitStable:
    """Soak until the interpreter's stability policy says the die is stable at the setpoint.

    ``n_positions``: the positions the sweep after it will measure (the
    predictive policy budgets the die's drift over that sweep); ``edge``: the
    coldest or hottest step (it bounds the thermal model's valid range).
    """

    step: int
    setpoint_c: float
    resumed: bool
    n_positions: int
    edge: bool


@dataclass(frozen=True)
class Checkpoint:
    """A safe point: pause and abort are applied here (and nowhere in between)."""


@dataclass(frozen=True)
class Move:
    """Put the sensor in orientation ``ref_g`` (unit gravity vector, sensor frame)."""

    step: int
    position: int
    ref_g: tuple[float, float, float]


@dataclass(frozen=True)
class Settle:
    """Wait for the table's ringing to die out before acquiring (s)."""

    settle_s: float


@dataclass(frozen=True)
class Acquire:
    """Average ``n_samples`` raw samples; the interpreter returns the acquisition.

    ``sensor``: which sensor of a several-sensor campaign (``None``: the one sensor);
    the interpreter returns ``None`` for a sensor it has dropped.
    """

    step: int
    position: int
    n_samples: int
    sensor: str | None = None


@dataclass(frozen=True)
class Save:
    """Store the acquisition of (step, position); ``next_position`` is the cursor after it."""

    step: int
    position: int
    setpoint_c: float
    ref_g: tuple[float, float, float]
    acquisition: Any
    next_position: int
    # Several sensors: ``acquisition`` is {serial: acquisition or None}, these serials, in order.
    sensors: tuple[str, ...] = ()


@dataclass(frozen=True)
class Fit:
    """Fit the calibration model to everything saved."""


Msg = Configure | SetChamber | WaitStable | Checkpoint | Move | Settle | Acquire | Save | Fit
Plan = Generator[Msg, Any, None]


@dataclass(frozen=True)
class PlanSpec:
    """The part of a campaign spec the plan reads (RunSpec satisfies it too)."""

    setpoints_c: Sequence[float]
    samples_per_position: int
    settle_s: float = 5.0
    ramp_c_per_min: float = 1.0
    range_g: float = 2.0
    odr_hz: float = 62.5


def campaign_plan(spec: Any, refs: np.ndarray,
                  done: Iterable[tuple[int, int]] = (), sensors: Sequence[str] = ()) -> Plan:
    """The campaign, once: ramp, soak, then move/settle/acquire/save per position, then fit.

    ``spec`` needs ``setpoints_c``, ``samples_per_position``, ``settle_s``,
    ``ramp_c_per_min``, ``range_g`` and ``odr_hz`` (a :class:`PlanSpec` or the
    engine's RunSpec); ``refs`` is the (n, 3) schedule of unit gravity vectors.
    ``sensors`` (two or more serials, issue 12): every position is acquired once per
    sensor (one ``Acquire`` each, in order) and saved by one ``Save`` carrying them all,
    so the interpreter stores a position for every sensor in one transaction.
    """
    several = tuple(str(s) for s in sensors) if len(sensors) > 1 else ()
    stored = set(done)
    refs = np.asarray(refs, float)
    n_pos = refs.shape[0]
    setpoints_c = [float(v) for v in spec.setpoints_c]
    lo_c, hi_c = min(setpoints_c), max(setpoints_c)
    yield Configure(float(spec.range_g), float(spec.odr_hz))
    yield Checkpoint()
    for step, setpoint_c in enumerate(setpoints_c):
        missing = [p for p in range(n_pos) if (step, p) not in stored]
        if not missing:
            continue
        yield SetChamber(step, setpoint_c, float(spec.ramp_c_per_min))
        yield WaitStable(step, setpoint_c, resumed=len(missing) < n_pos,
                         n_positions=len(missing), edge=setpoint_c in (lo_c, hi_c))
        for k, pos in enumerate(missing):
            ref = (float(refs[pos, 0]), float(refs[pos, 1]), float(refs[pos, 2]))
            yield Checkpoint()
            yield Move(step, pos, ref)
            yield Settle(float(spec.settle_s))
            next_pos = missing[k + 1] if k + 1 < len(missing) else n_pos
            if several:
                by_sensor = {}
                for serial in several:
                    by_sensor[serial] = yield Acquire(step, pos, int(spec.samples_per_position),
                                                      serial)
                yield Save(step, pos, setpoint_c, ref, by_sensor, next_pos, several)
                continue
            acquisition = yield Acquire(step, pos, int(spec.samples_per_position))
            yield Save(step, pos, setpoint_c, ref, acquisition, next_pos)
    yield Fit()


def interpret(plan: Plan, handle: Any) -> None:
    """Run ``plan`` synchronously: ``handle(msg)`` executes a message and returns its result."""
    reply: Any = None
    try:
        while True:
            reply = handle(plan.send(reply))
    except StopIteration:
        return


# --- the dry-run interpreter ------------------------------------------------------------
DEFAULT_MOVE_S = 12.0  # table slew + in-position between orientations (seed Table 3 rigs)
DEFAULT_START_C = 23.0


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
            move_s: float = DEFAULT_MOVE_S, start_c: float = DEFAULT_START_C,
            done: Iterable[tuple[int, int]] = ()) -> DryRun:
    """Interpret the campaign plan without hardware: predicted duration and counts.

    ``spec`` is a campaign's JSON spec (the ``POST /campaigns`` body as a dict)
    or an already parsed ``RunSpec``; ``ValueError`` when it cannot be parsed.
    ``refs`` defaults to the spec's named schedule; ``soak_s`` to the nominal
    soak (``soak_min`` × 60: the predictive policy usually ends earlier, so
    the prediction is an upper estimate); ``move_s`` is the time per table
    move; ``start_c`` the chamber's temperature at the start. Ramps are
    predicted at the commanded rate, acquisitions at ``n_samples / odr_hz``.
    Pass ``done`` (stored (step, position) pairs) to predict the rest of a
    resumed campaign.
    """
    from service.engine.spec import parse_spec, schedule_refs

    if isinstance(spec, dict):
        spec = parse_spec(spec)
    if refs is None:
        refs = schedule_refs(spec.positions)
    if soak_s is None:
        soak_s = float(spec.stability.soak_s)
    state = {"c": float(start_c)}
    odr_hz = float(spec.odr_hz)
    out = DryRun(0.0, 0, int(np.asarray(refs).shape[0]), 0, 0.0, 0.0, 0.0)

    def handle(msg: Msg) -> Any:
        if isinstance(msg, SetChamber):
            dt_s = abs(msg.setpoint_c - state["c"]) / max(msg.ramp_c_per_min, 1e-6) * 60.0
            state["c"] = msg.setpoint_c
            out.ramp_s += dt_s
            out.n_steps += 1
            out.steps.append({"setpoint_c": msg.setpoint_c, "ramp_s": dt_s, "soak_s": 0.0,
                              "positions_s": 0.0})
        elif isinstance(msg, WaitStable):
            out.soak_s += soak_s
            out.steps[-1]["soak_s"] = soak_s
        elif isinstance(msg, Move | Settle | Acquire):
            dt_s = (move_s if isinstance(msg, Move) else msg.settle_s if isinstance(msg, Settle)
                    else msg.n_samples / odr_hz)
            out.positions_s += dt_s
            out.steps[-1]["positions_s"] += dt_s
        elif isinstance(msg, Save):
            out.n_saves += 1
        return None

    interpret(campaign_plan(spec, refs, done), handle)
    out.duration_s = out.ramp_s + out.soak_s + out.positions_s
    return out
