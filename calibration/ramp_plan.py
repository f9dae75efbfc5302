"""The ramp-method campaign as a plan: the chamber never waits, the table never stops.

The seed paper's second temperature method (Sec. 1: "the ramp method assumes the
sensor temperature varies with time"): instead of soaking each setpoint until the die
is stable, the chamber ramps through the setpoints' range and back while the table
sweeps the position schedule over and over; every capture is stored with each sensor's
own die temperature (``sensor_c``) and the chamber air (``chamber_c``), and the
calibration fits the twelve SFEM parameters as polynomials of each reading's own die
temperature (:mod:`calibration.continuous`, no steps).

Like :func:`calibration.campaign_plan.campaign_plan` it is one generator written with
the engine's verbs and plan stubs (``SetChamber`` commands the chamber and does not wait
for it, ``ReadChamber``, ``measure_position`` with ``Save(band=False)``), run by several
interpreters: the engine (devices), the offline twin (:mod:`simulators.ramp_campaign_sim`)
and the dry run (:func:`predict_ramp`). A leg ends when the air is within ``tol_c`` of
its target and the working setpoint (where the controller has one) is there; the
chamber is read after every capture until then.

**Legs.** ``lo``/``hi`` are the lowest and highest setpoint. From the chamber's
temperature at the start the legs are: to ``lo``, to ``hi``, back to ``end_c`` (the
rig's safe temperature, clamped into the range; for a campaign started at ambient that
is its start, so every temperature of the range is crossed once heating and once
cooling: rate- and direction-dependent effects are seen with both signs). The cold end
comes first: the parts then end on a cooling leg from the hot end, dry, instead of
being warmed from −40 °C in the chamber's moist air at the end (frost on the dies while
they are measured). Travel is 2·(hi − lo) either way.

**Sweeps.** The table visits the schedule in the campaign's position order, reversed
on every other sweep (the return move of a repeated tour is saved, and within the
ramp each orientation is met early and late in a sweep on alternate passes, so no
orientation is tied to one side of the die's drift). A sweep is one ``step`` index in
the stored measurements (UNIQUE(campaign, step, position)); a leg may end inside a
sweep, the sweep goes on into the next leg. Every capture is saved without the
soak's setpoint band (the air is meant to be away from the setpoint), with the setpoint
in force as ``setpoint_c``: the ramping working setpoint on the way (so the calibration
never takes a sweep for a soak at a held setpoint), the leg's target while holding.

**Holds, only where the physics needs them.** A die lags its air first-order with its
time constant τ: during a ramp at r °C/min it trails by r·τ (30 °C for τ = 15 min at
2 °C/min). At a *turnaround* (a leg whose next leg reverses direction) the air
reaching the range end is not enough: reversed at once, the die would turn back r·τ
short of it and the range end would never be measured. So the chamber holds there,
the table still sweeping, until every die is within ``edge_gap_c`` of where it
settles. The remaining approach is measured, not assumed: with the air constant a
die's mean over consecutive blocks of captures of equal duration changes
geometrically, d₂ = q·d₁, and the rest of its approach is d₂·q/(1 − q) (Aitken's
extrapolation: offset-free, so the ADXL355 channel's ±2 °C offset does not matter).
``edge_gap_c`` is the calibration's :data:`calibration.thermal.RANGE_MARGIN_C`: the
model's valid range is the dies' coverage widened by it, so a die that came within it
of the end makes the end valid. The hold lasts τ·ln(r·τ/edge_gap_c) for a first-order
die (51 min for τ = 15 min at 2 °C/min); it is capped by the soak cap
(``max_soak_min``). No hold at the start (the chamber leaves from where it stands) and
none at the end (the range is already covered both ways there).

**Resume.** Pass the stored (step, position) pairs as ``done`` and the number of legs
finished (:func:`legs_done_from`, from the stored rows' setpoints in force): stored captures are
skipped, the sweep count continues, and the current leg is commanded again from
wherever the chamber now is (a hold restarts: the die may have drifted meanwhile). A
hold whose stored captures already end it (:func:`hold_ended`: the interruption came
after its end, before the next leg's first capture was stored) counts as finished
(:func:`resumed_legs_done`): the resume goes on with the next leg.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.campaign_plan import (
    ANY_SENSOR,
    Acquire,
    Configure,
    Fit,
    Move,
    ReadChamber,
    Save,
    SetChamber,
    Settle,
    interpret,
    measure_position,
    visit_orders,
)
from calibration.thermal_plant import AMBIENT_C, DEFAULT_AIR_TAU_S, lag_step, rate_limited

# calibration.thermal.RANGE_MARGIN_C (not imported: scipy); tests/calibration checks equality.
EDGE_GAP_C = 1.0
# The die lag the dry run assumes when the rig says nothing: the twin's ADXL355 fixture
# (simulators.chamber_sim.ChamberPhysics.die_tau_s) and the 32–35 min soaks per step measured
# with it. The engine does not use it: its holds are measured on the dies themselves.
PRIOR_DIE_TAU_S = 900.0
# The shortest block of captures a die's approach is judged on (its mean's channel noise
# 0.1 °C / √4 = 0.05 °C), and the blocks' share of a sweep.
MIN_BLOCK = 4
# A die whose block means change by less than this many noise sd is standing still.
STILL_SIGMAS = 3.0
# A table move the plan budgets when it caps a hold in captures (slew + in-position, s).
TYPICAL_MOVE_S = 12.0
# The air counts as arrived within this of the leg's target (the soak's default tol_c).
DEFAULT_ARRIVED_C = 0.3
# A working setpoint this close to a leg's target is at it (as the runner's WaitChamber).
TARGET_TOL_C = 1e-3


@dataclass(frozen=True)
class Leg:
    """One leg of the chamber's program: ramp to ``target_c``; ``hold``: a turnaround."""

    index: int
    target_c: float
    hold: bool


def ramp_legs(setpoints_c: Sequence[float], start_c: float, end_c: float) -> list[Leg]:
    """The chamber's legs (module docstring): to lo, to hi, back to ``end_c`` (clamped).

    A leg holds when the next one reverses direction (a turnaround); a leg that goes
    nowhere after the first (``end_c`` at ``hi``) is dropped.
    """
    lo, hi = float(min(setpoints_c)), float(max(setpoints_c))
    end = min(max(float(end_c), lo), hi)
    targets = [lo, hi] + ([end] if end != hi else [])
    legs = []
    here = float(start_c)
    for i, target in enumerate(targets):
        after = targets[i + 1] if i + 1 < len(targets) else None
        going = np.sign(target - here)
        turning = after is not None and going != 0 and np.sign(after - target) == -going
        # the first leg arriving at lo from below, or already there: no turnaround
        legs.append(Leg(i, target, bool(turning)))
        here = target
    return legs


def legs_done_from(stored_setpoints_c: Sequence[float], legs: Sequence[Leg]) -> int:
    """Legs finished before an interruption, from the stored rows' setpoints in time order.

    Every capture is saved with the setpoint in force (:func:`setpoint_in_force`): the
    ramping working setpoint on the way, the leg's target once there. A leg is finished
    when its target was reached and a later capture's setpoint left it (towards the next).
    """
    leg, reached = 0, False
    for sp in stored_setpoints_c:
        at_target = abs(float(sp) - legs[leg].target_c) < TARGET_TOL_C
        if at_target:
            reached = True
        elif reached and leg + 1 < len(legs):
            leg, reached = leg + 1, abs(float(sp) - legs[leg + 1].target_c) < TARGET_TOL_C
    return leg


def hold_rules(spec: Any, n_pos: int) -> tuple[int, int]:
    """A hold's block (captures per block of :func:`remaining_approach_c`) and its cap in
    captures (the soak cap over a typical capture's time, at least three blocks)."""
    settle_s = float(spec.settle_s)
    capture_s = int(spec.samples_per_position) / float(spec.odr_hz)
    block = max(MIN_BLOCK, n_pos // 2)
    cap = max(3 * block, math.ceil(max_hold_s(spec) / (TYPICAL_MOVE_S + settle_s + capture_s)))
    return block, cap


def _waiting_die(since: dict[str, list[float]], block: int, edge_gap_c: float,
                 first: str | None) -> str | None:
    """The first die (``first`` asked first) still more than ``edge_gap_c`` from where it
    settles; None when every die is within it (and there is one)."""
    if not since:
        return ""
    for key in sorted(since, key=lambda k: k != first):
        if remaining_approach_c(since[key], block) > edge_gap_c:
            return key
    return None


def hold_ended(dies_c: dict[str, Sequence[float]], spec: Any, n_pos: int,
               edge_gap_c: float = EDGE_GAP_C) -> bool:
    """Whether a hold's captures end it, as the plan decides after each: ``dies_c`` each
    die's readings since the air arrived, in time order. Every die within ``edge_gap_c``
    of where it settles, or the cap's number of captures."""
    block, cap = hold_rules(spec, n_pos)
    if max((len(v) for v in dies_c.values()), default=0) >= cap:
        return True
    return _waiting_die({k: list(v) for k, v in dies_c.items() if len(v)}, block,
                        edge_gap_c, None) is None


def resumed_legs_done(stored_setpoints_c: Sequence[float],
                      stored_dies_c: dict[str, Sequence[float]], legs: Sequence[Leg],
                      spec: Any, n_pos: int, edge_gap_c: float = EDGE_GAP_C) -> int:
    """Legs finished before an interruption (:func:`legs_done_from`), a turnaround hold
    counted finished when its stored captures end it (:func:`hold_ended`): the plan had
    ended it and moved on when the run stopped, before the next leg's first capture.
    ``stored_dies_c``: each die's stored readings, in the rows' time order (one per row of
    ``stored_setpoints_c``)."""
    done = legs_done_from(stored_setpoints_c, legs)
    leg = legs[done]
    if not leg.hold or not len(stored_setpoints_c):
        return done
    held = 0  # the trailing rows at the leg's target: the hold's captures
    for sp in reversed(stored_setpoints_c):
        if abs(float(sp) - leg.target_c) >= TARGET_TOL_C:
            break
        held += 1
    if not held:
        return done
    dies = {k: [float(x) for x in v[len(v) - held:] if math.isfinite(float(x))]
            for k, v in stored_dies_c.items()}
    return done + 1 if hold_ended(dies, spec, n_pos, edge_gap_c) else done


def setpoint_in_force(status: Any, target_c: float, arrived: bool) -> float:
    """A capture's ``setpoint_c``: the chamber setpoint in force (recording format v1).

    On the way it is the controller's ramping working setpoint (a controller without one:
    the air, within its lag of it), so the calibration never takes a sweep's rows for a
    soak at a held setpoint; once the air has arrived, the leg's target."""
    if arrived:
        return float(target_c)
    wsp = getattr(status, "working_setpoint_c", None)
    return float(getattr(status, "process_c", target_c) if wsp is None else wsp)


def sweep_order(base: Sequence[int], sweep: int) -> list[int]:
    """Sweep ``sweep``'s order: the base order, reversed on odd sweeps."""
    return list(base) if sweep % 2 == 0 else list(reversed(base))


def remaining_approach_c(die_c: Sequence[float], block: int) -> float:
    """A die's remaining approach to where it settles, °C, at its last capture, from its
    readings since the air stopped (module docstring, "Holds"): inf until three blocks of
    ``block`` captures exist (captures equally spaced in time, as a sweep's are on average).

    Blocks are the last three runs of ``block`` consecutive captures; d₁, d₂ the changes of
    their means. A die standing still within the noise (|d₂| within
    :data:`STILL_SIGMAS` sd of the block means' difference, the sd estimated from the
    captures' scatter about a line within each block) has 0 left.
    """
    x = np.asarray(die_c, float)
    if x.size < 3 * block:
        return math.inf
    blocks = x[-3 * block:].reshape(3, block)
    means = blocks.mean(axis=1)
    d1, d2 = means[1] - means[0], means[2] - means[1]
    t = np.arange(block) - (block - 1) / 2.0
    slopes = blocks @ t / float(t @ t)
    resid = blocks - means[:, None] - slopes[:, None] * t
    sd_c = float(np.sqrt(np.sum(resid**2) / max(3 * (block - 2), 1)))
    sd_d = sd_c * math.sqrt(2.0 / block)
    if abs(d2) <= STILL_SIGMAS * sd_d:
        return 0.0
    if d1 == 0.0 or d2 / d1 <= 0.0 or d2 / d1 >= 1.0:
        return math.inf  # not (yet) a decaying approach
    q = d2 / d1  # e^(−block/τ), τ in captures
    # d₂·q/(1 − q) is the last block *mean*'s gap; the last capture is (block − 1)/2
    # captures later: its gap is that times mean-to-last of an exponential over the block
    per = q ** (1.0 / block)
    last = q ** ((block - 1.0) / block) * block * (1.0 - per) / (1.0 - q)
    return abs(d2) * q / (1.0 - q) * last


def _dies(reply: Any) -> dict[str, float]:
    """Die temperature per sensor from an ``Acquire`` reply (an acquisition, the engine's
    (acquisition, flags, attempts), or {serial: either or None})."""
    def one(r: Any) -> float | None:
        if r is None:
            return None
        if isinstance(r, tuple):
            r = r[0]
        v = getattr(r, "sensor_c", None)
        return None if v is None or not math.isfinite(float(v)) else float(v)

    if isinstance(reply, dict):
        out = {str(k): one(v) for k, v in reply.items()}
        return {k: v for k, v in out.items() if v is not None}
    v = one(reply)
    return {} if v is None else {"": v}


def _get(spec: Any, name: str, default: Any) -> Any:
    """A spec key from a CampaignSpec, a RunSpec (its ``stability`` config) or a PlanSpec."""
    if hasattr(spec, name):
        return getattr(spec, name)
    stab = getattr(spec, "stability", None)
    return getattr(stab, name, default) if stab is not None and not isinstance(stab, str) \
        else default


def max_hold_s(spec: Any) -> float:
    """The hold cap: the soak cap (``max_soak_min``, default 2 × ``soak_min``), s."""
    if hasattr(spec, "max_soak_s"):
        return float(spec.max_soak_s)
    stab = getattr(spec, "stability", None)
    if stab is not None and hasattr(stab, "max_soak_s"):
        return float(stab.max_soak_s)
    soak_min = float(getattr(spec, "soak_min", 60.0))
    cap_min = getattr(spec, "max_soak_min", None)
    return 60.0 * (2.0 * soak_min if cap_min is None else float(cap_min))


def ramp_plan(spec: Any, refs: np.ndarray, *, end_c: float = AMBIENT_C,
              done: Iterable[tuple[int, int]] = (), legs_done: int = 0,
              sensors: Sequence[str] = (), angles_deg: np.ndarray | None = None,
              edge_gap_c: float = EDGE_GAP_C) -> Any:
    """The ramp campaign, once (module docstring). A generator of plan messages: the
    engine's verbs (``SetChamber`` commands without waiting, ``ReadChamber``) and its
    :func:`calibration.campaign_plan.measure_position` stub with the band off.

    ``spec`` needs ``setpoints_c``, ``samples_per_position``, ``settle_s``,
    ``ramp_c_per_min``, ``range_g``, ``odr_hz`` and may give ``position_order`` /
    ``position_order_seed``, ``tol_c`` and the soak cap; ``end_c`` is where the last leg
    goes (the rig's safe temperature); ``done``/``legs_done`` resume (module docstring).
    ``sensors``: the campaign's serials (none: the plan names one, ``ANY_SENSOR``).
    """
    serials = tuple(str(s) for s in sensors) or (ANY_SENSOR,)
    stored = set(done)
    refs = np.asarray(refs, float)
    n_pos = refs.shape[0]
    rate = float(spec.ramp_c_per_min)
    if not rate > 0:  # 0 is a soak's step (calibration/campaign_spec.py): no ramp to sweep
        raise ValueError(f"a ramp campaign needs a controlled ramp: ramp_c_per_min "
                         f"{rate:g} °C/min, expected > 0")
    arrived_c = float(_get(spec, "tol_c", DEFAULT_ARRIVED_C))
    n = int(spec.samples_per_position)
    settle_s = float(spec.settle_s)
    block, hold_cap = hold_rules(spec, n_pos)
    base = visit_orders(_OneSweep(spec), refs, angles_deg)[0]

    yield Configure(float(spec.range_g), float(spec.odr_hz))
    status = yield ReadChamber()
    start_c = float(getattr(status, "process_c", AMBIENT_C))
    legs = ramp_legs(list(spec.setpoints_c), start_c, end_c)
    leg_i = min(int(legs_done), len(legs) - 1)
    sweep = max((s for s, _ in stored), default=0)
    queue = [p for p in sweep_order(base, sweep) if (sweep, p) not in stored]

    while leg_i < len(legs):
        leg = legs[leg_i]
        yield SetChamber(leg.index, leg.target_c, rate)  # the step of a SetChamber: its leg
        arrived_at: int | None = None  # captures since the air arrived (hold legs)
        since: dict[str, list[float]] = {}
        waiting_on: str | None = None
        captures = 0
        status = yield ReadChamber()
        while True:
            air_c = float(getattr(status, "process_c", math.nan))
            wsp = getattr(status, "working_setpoint_c", None)  # None: a controller without
            here = (abs(air_c - leg.target_c) <= arrived_c
                    and (wsp is None or abs(float(wsp) - leg.target_c) < TARGET_TOL_C))
            if here and not leg.hold:
                break
            if here and arrived_at is None:
                arrived_at = captures
            if arrived_at is not None:
                # the die that said "not yet" last is asked first; the first "not yet" ends
                # the round (the slowest die decides; one estimate per capture, not one per die)
                waiting = _waiting_die(since, block, edge_gap_c, waiting_on)
                waiting_on = waiting or waiting_on
                if waiting is None or captures - arrived_at >= hold_cap:
                    break
            if not queue:
                sweep += 1
                queue = [p for p in sweep_order(base, sweep) if (sweep, p) not in stored]
                continue
            pos = queue.pop(0)
            ref = (float(refs[pos, 0]), float(refs[pos, 1]), float(refs[pos, 2]))
            next_pos = queue[0] if queue else n_pos
            # each capture stored with the setpoint in force, without the band
            setpoint_c = setpoint_in_force(status, leg.target_c, arrived_at is not None)
            reply = yield from measure_position(sweep, pos, setpoint_c, ref, next_pos,
                                                serials, n, settle_s, band=False)
            captures += 1
            if arrived_at is not None:
                for key, die_c in _dies(reply).items():
                    since.setdefault(key, []).append(die_c)
            else:  # the chamber is read until it arrives; then the dies decide the hold
                status = yield ReadChamber()
        leg_i += 1
    yield Fit()


@dataclass(frozen=True)
class _OneSweep:
    """The spec seen as one step, for :func:`visit_orders` (the sweep's base order)."""

    spec: Any

    @property
    def setpoints_c(self) -> list[float]:
        return [0.0]

    def __getattr__(self, name: str) -> Any:
        if name == "rate_gain":  # a ramp never parks the table at home between steps
            return "assumed"
        return getattr(self.spec, name)


# --- the prediction: the plan interpreted with a first-order plant -----------------------
@dataclass
class RampPrediction:
    """What a ramp campaign will do on a plant with die lag ``die_tau_s``."""

    duration_s: float
    n_sweeps: int  # the campaign's sweeps: those stored before a resume, then the plan's
    n_saves: int  # the captures still to store
    die_tau_s: float
    legs: list[dict[str, float]] = field(default_factory=list)  # target_c, ramp_s, hold_s
    start_c: float = AMBIENT_C


@dataclass
class _Status:
    process_c: float
    setpoint_c: float
    working_setpoint_c: float


@dataclass
class _Reading:
    sensor_c: float


@dataclass
class RampPlant:
    """Air behind a rate-limited working setpoint and dies behind the air, first order.

    The time base of the prediction and of the offline twin
    (:mod:`simulators.ramp_campaign_sim`): ``advance(dt)`` integrates at ``dt_s``.
    """

    air_c: float
    die_tau_s: Sequence[float]
    air_tau_s: float = DEFAULT_AIR_TAU_S
    dt_s: float = 2.0
    t_s: float = 0.0
    setpoint_c: float = field(init=False)
    wsp_c: float = field(init=False)
    rate_c_per_min: float = 1.0
    die_c: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.setpoint_c = self.wsp_c = self.air_c
        self.die_c = np.full(len(self.die_tau_s), self.air_c, float)

    def advance(self, dt_s: float) -> None:
        left = float(dt_s)
        taus = np.asarray(self.die_tau_s, float)
        while left > 1e-12:
            dt = min(self.dt_s, left)
            self.wsp_c = rate_limited(self.wsp_c, self.setpoint_c,
                                      self.rate_c_per_min / 60.0 * dt)
            new_air = lag_step(self.air_c, self.wsp_c, dt, self.air_tau_s)
            mean_air = 0.5 * (self.air_c + new_air)
            self.die_c = mean_air + (self.die_c - mean_air) * np.exp(-dt / taus)
            self.air_c = float(new_air)
            self.t_s += dt
            left -= dt

    def status(self) -> _Status:
        return _Status(self.air_c, self.setpoint_c, self.wsp_c)


def predict_ramp(spec: Any, refs: np.ndarray, *, start_c: float = AMBIENT_C,
                 end_c: float = AMBIENT_C, die_tau_s: float = PRIOR_DIE_TAU_S,
                 move_s: Callable[[tuple[float, float, float]], float] | float = TYPICAL_MOVE_S,
                 angles_deg: np.ndarray | None = None,
                 done: Iterable[tuple[int, int]] = (), legs_done: int = 0) -> RampPrediction:
    """Predicted duration of a ramp campaign: :func:`ramp_plan` interpreted on a
    :class:`RampPlant` whose one die lags its air by ``die_tau_s`` (noise-free, so the
    holds end as the engine's would on such a die). ``move_s``: per move, s, or a function
    of the move's reference (the table's travel from the pose before)."""
    plant = RampPlant(float(start_c), [float(die_tau_s)])
    odr_hz = float(spec.odr_hz)
    out = RampPrediction(0.0, 0, 0, float(die_tau_s), start_c=float(start_c))
    sweeps: set[int] = set()
    state: dict[str, Any] = {"leg": None, "arrived": None}

    def handle(msg: Any) -> Any:
        if isinstance(msg, SetChamber):
            _close_leg(out, state, plant)
            plant.setpoint_c, plant.rate_c_per_min = msg.setpoint_c, msg.ramp_c_per_min
            state["leg"] = {"target_c": msg.setpoint_c, "start_s": plant.t_s}
            state["arrived"] = None
            return None
        if isinstance(msg, ReadChamber):
            st = plant.status()
            leg = state["leg"]
            if (leg is not None and state["arrived"] is None
                    and abs(st.process_c - leg["target_c"]) <= DEFAULT_ARRIVED_C):
                state["arrived"] = plant.t_s
            return st
        if isinstance(msg, Move):
            plant.advance(move_s(msg.ref_g) if callable(move_s) else float(move_s))
        elif isinstance(msg, Settle):
            plant.advance(msg.settle_s)
        elif isinstance(msg, Acquire):
            plant.advance(msg.n_samples / odr_hz)
            reading = _Reading(float(plant.die_c[0]))
            return dict.fromkeys(msg.sensors, reading)
        elif isinstance(msg, Save):
            out.n_saves += 1
            sweeps.add(msg.step)
        elif isinstance(msg, Fit):
            _close_leg(out, state, plant)
        return None

    done = set(done)
    interpret(ramp_plan(spec, refs, end_c=end_c, done=done, legs_done=legs_done,
                        angles_deg=angles_deg), handle)
    out.duration_s = plant.t_s
    # sweeps are numbered on from the stored ones: the last one's index + 1 is the count a
    # progress "sweep N of about M" means (not the resumed plan's new sweeps alone)
    out.n_sweeps = max(sweeps | {s for s, _ in done}, default=-1) + 1
    return out


def travel_move_s(refs: np.ndarray, angles_deg: np.ndarray, slew_deg_per_s: float,
                  accel_deg_per_s2: float, in_position_s: float = 1.0
                  ) -> Callable[[tuple[float, float, float]], float]:
    """A move-time function for :func:`predict_ramp`: the slowest axis of the table's travel
    from the pose before (home at the start) on the trapezoidal profile, plus the
    in-position poll (as the soak campaign's dry run predicts its moves)."""
    from calibration.position_order import axis_move_s

    refs = np.asarray(refs, float)
    poses = np.asarray(angles_deg, float)
    pose_of = {tuple(np.round(r, 12)): poses[i] for i, r in enumerate(refs)}
    here = {"deg": np.zeros(poses.shape[1])}

    def move(ref_g: tuple[float, float, float]) -> float:
        to = pose_of[tuple(np.round(np.asarray(ref_g, float), 12))]
        dt_s = float(axis_move_s(to - here["deg"], slew_deg_per_s, accel_deg_per_s2).max())
        here["deg"] = to
        return dt_s + in_position_s

    return move


def describe_prediction(pred: RampPrediction, rate_c_per_min: float) -> str:
    """One line: the legs, the holds and why, the sweeps and the duration."""
    path = " → ".join(f"{v:g}" for v in [pred.start_c] + [leg["target_c"] for leg in pred.legs])
    holds = ", ".join(f"{leg['hold_s'] / 60:.0f} min at {leg['target_c']:g} °C"
                      for leg in pred.legs if leg["hold_s"] > 0)
    return (f"ramp {path} °C at {rate_c_per_min:g} °C/min, holds {holds or 'none'} (until the "
            f"dies are within {EDGE_GAP_C:g} °C of the range ends; predicted for a die lag of "
            f"{pred.die_tau_s / 60:.0f} min, measured on the dies at run time), "
            f"{pred.n_sweeps} sweeps, {pred.n_saves} captures, predicted duration "
            f"{pred.duration_s:.0f} s ({pred.duration_s / 3600.0:.2f} h of rig time)")


def _close_leg(out: RampPrediction, state: dict[str, Any], plant: RampPlant) -> None:
    leg = state["leg"]
    if leg is None:
        return
    arrived = plant.t_s if state["arrived"] is None else state["arrived"]
    out.legs.append({"target_c": leg["target_c"], "ramp_s": arrived - leg["start_s"],
                     "hold_s": plant.t_s - arrived})
    state["leg"] = None
