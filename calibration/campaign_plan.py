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
* the service's dry run (:func:`service.dry_run.dry_run`) predicts the duration
  and counts without any hardware.

It is pure protocol (numpy only), so the engine and the simulators both import
it without either climbing into the other.

The model is bluesky's RunEngine: a plan yields messages, the interpreter
executes each and ``send``\\ s the result back (``Acquire`` returns the
acquisition the following ``Save`` stores). Resuming is a replay of the same
plan that skips what is already stored: pass the stored (step, position)
pairs as ``done``; a step with every position stored is skipped entirely, a
step with some stored is re-ramped (idempotent) and re-soaked as ``resumed``.

A step's positions are visited in the spec's ``position_order``
(:func:`calibration.position_order.step_orders`: least table travel, a seeded
random or balanced order per plateau, or the schedule's). The order of every
step is computed from the whole campaign, never from what is stored, so a
resumed step visits its missing positions in the order it had.
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Configure:
    """Configure the accelerometer (range ±g, output data rate Hz)."""

    range_g: float
    odr_hz: float


@dataclass(frozen=True)
class SetChamber:
    """Command the chamber to ``setpoint_c`` at ``ramp_c_per_min`` and run it; done once
    commanded (it does not wait for the chamber to get there: :class:`WaitChamber`)."""

    step: int
    setpoint_c: float
    ramp_c_per_min: float


@dataclass(frozen=True)
class WaitChamber:
    """Wait until the chamber has arrived at ``setpoint_c``: its working setpoint at the
    setpoint (a controller without one: skipped) and its PV within the stability
    tolerance. The interpreter bounds the wait (twice the nominal ramp plus a max
    soak) and, measuring the rate gain, probes the dies meanwhile."""

    step: int
    setpoint_c: float


@dataclass(frozen=True)
class ReadChamber:
    """Read the chamber; the interpreter returns its status
    (``drivers.protocols.ChamberStatus``)."""


@dataclass(frozen=True)
class Home:
    """Put the table at its home pose (all axes 0), e.g. before a ramp whose dies are
    probed at one pose (the measured rate gain)."""

    step: int


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
    # How many steps of the campaign (this one included) visit the positions in this step's
    # order: an error that depends on the slot in the sweep (the die's curvature the per-step
    # line cannot follow) then meets the same position at every such step and is not averaged
    # over them (stability.decide's ``order_repeats``).
    order_repeats: int = 1


@dataclass(frozen=True)
class Wait:
    """Let ``seconds`` of the clock pass (a poll period)."""

    seconds: float


@dataclass(frozen=True)
class PollChamber:
    """One poll of a ramp (:func:`wait_for_chamber`): read the chamber (probing the dies
    where the rate gain is measured); the reply is a :class:`Poll`, done once arrived."""

    step: int
    setpoint_c: float


@dataclass(frozen=True)
class PollSoak:
    """One poll of a soak (:func:`soak_until_stable`): read the chamber, probe the dies
    and decide (seed Sec. 3's soak rule for every die, the slowest ending it: the engine's
    pure ``service.engine.polls.decide_round``); the reply is a :class:`Poll`, done once
    stable."""

    soak: WaitStable


@dataclass(frozen=True)
class Poll:
    """A poll's reply: ``done``, or wait ``wait_s`` before the next."""

    done: bool
    wait_s: float = 0.0


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
    """Average ``n_samples`` raw samples of every sensor in ``sensors``, read *at once*
    (one capture time for all, issue 12; one sensor is a list of one).

    The interpreter returns ``{serial: acquisition}`` with ``None`` for a sensor it
    has dropped.
    """

    step: int
    position: int
    n_samples: int
    sensors: tuple[str, ...]


@dataclass(frozen=True)
class Save:
    """Store every sensor's acquisition of (step, position) with the cursor past it
    (``next_position``) in one transaction: a position is stored for every live sensor
    or for none. ``acquisition`` is ``Acquire``'s reply, {serial: acquisition or None}.

    Before storing, the interpreter checks the chamber (``band``: its PV within the
    campaign's band of ``setpoint_c``; off for a ramp, whose air is never in a
    setpoint band; alarms always) and each capture against its pose. The reply is
    ``None`` once stored, or :data:`RETAKE`: the capture was not stored (it read
    gravity from another direction than ``ref_g``) and the position must be measured
    again.
    """

    step: int
    position: int
    setpoint_c: float
    ref_g: tuple[float, float, float]
    acquisition: Any
    next_position: int
    sensors: tuple[str, ...]
    band: bool = True


# Save's reply when its capture was not stored and the position is to be measured again.
RETAKE = "retake"


@dataclass(frozen=True)
class Fit:
    """Fit the calibration model to everything saved."""


Msg = (Configure | SetChamber | WaitChamber | ReadChamber | Home | WaitStable | Checkpoint | Move
       | Settle | Acquire | Save | Fit | Wait | PollChamber | PollSoak)
Plan = Generator[Msg, Any, None]


# The campaign's commanded chamber ramp when its spec does not give one, °C/min: the API's
# default (service.engine.spec) and the plan's. The offline twin commands its own rig's
# rate (simulators.campaign_sim.RigPhysics, calibration.thermal_plant.DEFAULT_RAMP_C_PER_MIN,
# 2 °C/min), on which its recordings and the diagnosis' assumed ramp were measured.
CAMPAIGN_RAMP_C_PER_MIN = 1.0
# A ramp-method campaign's default, °C/min: the rate it measures at, not only how it moves
# between setpoints. At 2 °C/min 16 sensors take 0.243× the seed paper's 13.9 h (dry run),
# held-out error 1.03× the noise-limited oracle on the twin and 1.007× on the second,
# independently written generator; at 1 °C/min the same campaign takes 0.339× for no
# measurable gain (1.005×). docs/benchmarks.md, "gen2 ramps with the plan's legs".
RAMP_METHOD_C_PER_MIN = 2.0
# The serial a plan names when its interpreter models no particular sensor.
ANY_SENSOR = "sensor"


def visit_orders(spec: Any, refs: np.ndarray,
                 angles_deg: np.ndarray | None = None) -> list[list[int]]:
    """The order each step visits its positions (``spec.position_order``).

    ``angles_deg`` (n, axes): the rig's table pose of each reference
    (``drivers.geometry.angles_for_references`` for the 3-axis geometry); only the
    ``travel`` order reads it, and needs it: the plan does not guess a rig's geometry.
    """
    from calibration.position_order import step_orders  # heavy: imported on first use

    method = str(spec.position_order)
    refs = np.asarray(refs, float)
    n_steps = len(spec.setpoints_c)
    if method != "travel":
        angles_deg = np.zeros((refs.shape[0], 1))
    elif angles_deg is None:
        raise ValueError("the travel position order needs the table pose of each position "
                         "(angles_deg, e.g. drivers.geometry.angles_for_references(refs))")
    # A campaign measuring the rate gain sends the table home at each ramp (ramp_to): every
    # step then starts there.
    return step_orders(np.asarray(angles_deg, float), n_steps, method,
                       spec.position_order_seed,
                       home_each_step=spec.rate_gain == "measured")


# --- plan stubs: the protocol's pieces, composed with ``yield from`` -----------------------
def ramp_to(step: int, setpoint_c: float, ramp_c_per_min: float, *,
            home_first: bool = False) -> Plan:
    """Command the setpoint, then wait for the chamber to arrive.

    ``home_first`` (the rate gain measured): every soak's die probes are taken at one
    pose, home, so the table goes there once the setpoint is commanded: the move runs
    during the ramp instead of delaying it, and the ramp's probes start at home.
    """
    yield SetChamber(step, setpoint_c, ramp_c_per_min)
    if home_first:
        yield Home(step)
    yield WaitChamber(step, setpoint_c)


def wait_for_chamber(msg: WaitChamber) -> Plan:
    """:class:`WaitChamber` as the engine runs it: poll until the chamber has arrived."""
    while not (poll := (yield PollChamber(msg.step, msg.setpoint_c))).done:
        yield Checkpoint()
        yield Wait(poll.wait_s)


def soak_until_stable(msg: WaitStable) -> Plan:
    """:class:`WaitStable` as the engine runs it: poll the chamber and the dies until the
    decision says stable, waiting between polls as long as the decision asks."""
    while not (poll := (yield PollSoak(msg))).done:
        yield Checkpoint()
        yield Wait(poll.wait_s)


# The composite waits and the stubs an interpreter may expand them into: the engine runs
# these (its stability decision answers each poll); the offline simulator integrates a
# fixed soak and a rate-limited ramp instead, and the dry run adds their nominal times.
EXPANSIONS: dict[type, Any] = {WaitChamber: wait_for_chamber, WaitStable: soak_until_stable}


def measure_position(step: int, position: int, setpoint_c: float,
                     ref_g: tuple[float, float, float], next_position: int,
                     serials: tuple[str, ...], samples: int, settle_s: float,
                     band: bool = True) -> Plan:
    """Move to one position, settle, read every sensor at once and store the readings;
    again from the move while the interpreter answers the save with :data:`RETAKE`.
    Returns the stored readings (``Acquire``'s reply: the ramp plan reads the dies)."""
    while True:
        yield Checkpoint()
        yield Move(step, position, ref_g)
        yield Settle(settle_s)
        by_sensor = yield Acquire(step, position, samples, serials)
        if (yield Save(step, position, setpoint_c, ref_g, by_sensor, next_position, serials,
                       band)) != RETAKE:
            return by_sensor


def campaign_plan(spec: Any, refs: np.ndarray,
                  done: Iterable[tuple[int, int]] = (), sensors: Sequence[str] = (),
                  angles_deg: np.ndarray | None = None) -> Plan:
    """The campaign, once: ramp, soak, then move/settle/acquire/save per position, then fit.

    ``spec`` needs ``setpoints_c``, ``samples_per_position``, ``settle_s``,
    ``ramp_c_per_min``, ``range_g``, ``odr_hz``, ``position_order``, its seed and
    ``rate_gain`` (a :class:`calibration.campaign_spec.CampaignSpec`, or the engine's view);
    ``refs`` is the (n, 3) schedule of unit gravity vectors; ``angles_deg`` the
    rig's table pose of each (for the ``travel`` order; :func:`visit_orders`).
    ``sensors``: the campaign's serials, one or several (issue 12): every position is
    acquired by one ``Acquire`` naming them all (read concurrently) and saved by one
    ``Save`` carrying them all, so the interpreter stores a position for every sensor
    in one transaction. An interpreter that models no particular sensor (the offline
    simulator, the dry run) may pass none: the plan then names :data:`ANY_SENSOR`.
    """
    serials = tuple(str(s) for s in sensors) or (ANY_SENSOR,)
    stored = set(done)
    refs = np.asarray(refs, float)
    n_pos = refs.shape[0]
    setpoints_c = [float(v) for v in spec.setpoints_c]
    lo_c, hi_c = min(setpoints_c), max(setpoints_c)
    orders = visit_orders(spec, refs, angles_deg)
    yield Configure(float(spec.range_g), float(spec.odr_hz))
    yield Checkpoint()
    for step, setpoint_c in enumerate(setpoints_c):
        missing = [p for p in orders[step] if (step, p) not in stored]
        if not missing:
            continue
        yield from ramp_to(step, setpoint_c, float(spec.ramp_c_per_min),
                           home_first=getattr(spec, "rate_gain", "assumed") == "measured")
        yield WaitStable(step, setpoint_c, resumed=len(missing) < n_pos,
                         n_positions=len(missing), edge=setpoint_c in (lo_c, hi_c),
                         order_repeats=sum(o == orders[step] for o in orders))
        for k, pos in enumerate(missing):
            ref = (float(refs[pos, 0]), float(refs[pos, 1]), float(refs[pos, 2]))
            next_pos = missing[k + 1] if k + 1 < len(missing) else n_pos
            yield from measure_position(step, pos, setpoint_c, ref, next_pos, serials,
                                        int(spec.samples_per_position), float(spec.settle_s))
    yield Fit()


def interpret(plan: Plan, handle: Any) -> None:
    """Run ``plan`` synchronously: ``handle(msg)`` executes a message and returns its result."""
    reply: Any = None
    try:
        while True:
            reply = handle(plan.send(reply))
    except StopIteration:
        return
