"""The answers to the plan's polls, as pure functions: what a ramp's or a soak's poll
decides from what the engine read.

The plan polls (``calibration.campaign_plan.wait_for_chamber`` and
``soak_until_stable``: ``PollChamber``, ``PollSoak``); the engine
(:mod:`service.engine.runner`) reads the chamber, probes the dies, stores the probes
and publishes progress. What the readings mean is here, with no device and no
database: has the chamber arrived, how long may a ramp take, is the soak over (every
die's :func:`service.engine.stability.decide`, seed Sec. 3's soak rule, the slowest
die ending it), how long to wait before the next poll, what the step log says, and
whether the dies' temperature agrees with the chamber's PV.

A poll's state across a wait (:class:`RampState`, :class:`SoakState`) is plain data
the engine keeps; the time it holds excludes what was paused or suspended
(:func:`active_s`): paused time is never soak time and never a ramp's.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from drivers.protocols import ChamberStatus
from service.engine import progress, rate_gain, stability
from service.rig_plausibility import DIE_PV_TOLERANCE_C

# Shortest wait between two soak polls when the decision predicts stability sooner than a
# period (stability.next_poll_s): a poll costs a die probe (≈ 4 s at 250 samples) and a fit.
MIN_SOAK_POLL_S = 15.0
# The slowest die a lab mounts lags its air by minutes to tens of minutes; an hour's time
# constant is the most a gap to the PV is put down to lag (die_against_chamber).
DIE_LAG_TAU_MAX_S = 3600.0
# The dies' last reading: (clock s, median die °C).
DieTrack = tuple[float, float]
# The rate gain one die's decision uses (µg per °C/min, None: assumed): (serial, probes).
GainFor = Callable[[str, list[rate_gain.Probe]], float | None]


def active_s(now_s: float, start_s: float, held_total_s: float, held0_s: float) -> float:
    """Clock time since ``start_s`` less the time held (paused or suspended) since then:
    ``held_total_s`` now, ``held0_s`` at the start."""
    return now_s - start_s - (held_total_s - held0_s)


# --- a ramp's poll -----------------------------------------------------------------------
@dataclasses.dataclass
class RampState:
    """A ramp's state across its polls (the engine's ``PollChamber``)."""

    start_s: float
    held0_s: float  # held time before the ramp: not the ramp's
    dies: dict[str, list[rate_gain.Probe]]
    probe: bool  # the dies are probed (the rate gain measured)
    limit_s: float | None = None
    limit_basis: str = ""  # how limit_s was set, for the failure message


def wsp_at_target(status: ChamberStatus, target_c: float) -> bool:
    """The controller's setpoint, and its working setpoint where it has one, at the target
    (a controller without one: the PV within tolerance alone says it arrived)."""
    wsp_c = status.working_setpoint_c
    return ((wsp_c is None or abs(wsp_c - target_c) < 1e-3)
            and abs(status.setpoint_c - target_c) < 1e-3)


def chamber_arrived(status: ChamberStatus, target_c: float, tol_c: float) -> bool:
    """The ramp is over: the setpoints at the target and the PV within ``tol_c`` of it."""
    return wsp_at_target(status, target_c) and abs(status.process_c - target_c) <= tol_c


def ramp_limit_s(delta_c: float, rate_c_per_min: float | None,
                 max_soak_s: float) -> tuple[float, str]:
    """How long a ramp of ``|delta_c|`` may take (active s) before the chamber is called
    stuck, and the basis of that limit in words (for the failure message): twice the time
    at the moving rate plus the longest soak; at an unknown rate, at
    :data:`service.engine.progress.SLOWEST_RATE_C_PER_MIN`."""
    if rate_c_per_min is not None and rate_c_per_min > 0:
        rate = float(rate_c_per_min)
        basis = f"twice {abs(delta_c):.1f} °C at {rate:g} °C/min"
    else:
        rate = progress.SLOWEST_RATE_C_PER_MIN
        basis = (f"the chamber's rate is not known: twice {abs(delta_c):.1f} °C at "
                 f"{rate:g} °C/min, the slowest the engine waits for")
    return abs(delta_c) / rate * 60.0 * 2.0 + max_soak_s, basis + " + the longest soak"


# --- a soak's poll -----------------------------------------------------------------------
def recheck_config(cfg: stability.StabilityConfig, resumed: bool
                   ) -> stability.StabilityConfig:
    """The stability rule of a soak: a resumed step (soaked before the interruption) is
    re-checked, not re-soaked in full (predictive, no minimum soak, at most a dwell)."""
    if not resumed:
        return cfg
    return dataclasses.replace(
        cfg, policy="predictive" if cfg.policy == "fixed" else cfg.policy,
        min_soak_s=0.0, soak_s=min(cfg.soak_s, cfg.dwell_s),
    )


@dataclasses.dataclass
class SoakState:
    """A soak's state across its polls (the engine's ``PollSoak``)."""

    cfg: stability.StabilityConfig  # the soak's rule (recheck_config)
    sweep_s: float
    start_s: float
    held0_s: float  # held time before the soak: not the soak's
    dies: dict[str, list[rate_gain.Probe]]
    ch_t: list[float] = dataclasses.field(default_factory=list)
    ch_pv: list[float] = dataclasses.field(default_factory=list)
    ch_wsp: list[float] = dataclasses.field(default_factory=list)
    decision: stability.Decision = stability.Decision(False, "started")
    gains: dict[str, float | None] = dataclasses.field(default_factory=dict)
    waiting_on: str | None = None  # the die that said "not yet" last

    def record_chamber(self, now_s: float, status: ChamberStatus, target_c: float) -> None:
        """One chamber poll of the soak (a controller without a working setpoint: the PV
        alone says it has arrived)."""
        self.ch_t.append(now_s)
        self.ch_pv.append(status.process_c)
        self.ch_wsp.append(target_c if status.working_setpoint_c is None
                           else status.working_setpoint_c)


def decide_round(soak: SoakState, soaked_s: float, target_c: float, live: Sequence[str],
                 gain_for: GainFor, *, n_positions: int, edge: bool,
                 order_repeats: int) -> stability.Decision:
    """One soak poll's decision over the ``live`` dies (kept in ``soak``).

    Every die decides (:func:`stability.decide`) with its own rate gain
    (``gain_for``); the slowest one ends the soak. The die that kept the soak going
    last poll is asked first and the first "not yet" ends the round: the soak goes on
    whatever the others say, and on the poll that ends it every die has been asked
    (:func:`slowest_decision` then picks the slowest), so the outcome is that of
    asking all, at a fraction of the fits.
    """
    cfg = soak.cfg
    settled = stability.chamber_settled(np.array(soak.ch_t), np.array(soak.ch_pv),
                                        np.array(soak.ch_wsp), target_c, cfg.tol_c,
                                        cfg.dwell_s)
    dies = {k: v for k, v in soak.dies.items() if k in live}
    soak.gains = {k: gain_for(k, v) for k, v in dies.items()}
    decisions: list[stability.Decision] = []
    for key in sorted(dies, key=lambda k: k != soak.waiting_on):
        probes = dies[key]
        decisions.append(stability.decide(
            cfg, soaked_s, settled, np.array([p.clock_s for p in probes]),
            np.array([p.sensor_c for p in probes]), sweep_s=soak.sweep_s,
            n_positions=n_positions, edge=edge, rate_gain_ug_per_c_per_min=soak.gains[key],
            order_repeats=order_repeats))
        if not decisions[-1].stable:
            soak.waiting_on = key
            break
    soak.decision = slowest_decision(decisions)
    return soak.decision


def slowest_decision(decisions: Sequence[stability.Decision]) -> stability.Decision:
    """The soak decision over every die: not stable while any is not; the slowest reports.

    While some die is not stable its decision is returned (why we wait); once all are,
    the one with the longest time constant (the slowest die, which decided the end).
    """
    if not decisions:
        raise ValueError("no sensor left to decide the soak")
    waiting = [d for d in decisions if not d.stable]
    if waiting:
        return waiting[0]
    capped = [d for d in decisions if d.max_soak_reached]
    if capped:
        return capped[0]
    return max(decisions, key=lambda d: -math.inf if d.tau_s is None else d.tau_s)


def soak_poll_wait_s(decision: stability.Decision, poll_s: float) -> float:
    """Wait before the next soak poll: sooner than a whole period when the die is predicted
    to meet its budgets sooner (the soak ends at a poll: a fixed period overshoots by half
    of one on average), never sooner than :data:`MIN_SOAK_POLL_S`."""
    return stability.next_poll_s(decision, poll_s, min(poll_s, MIN_SOAK_POLL_S))


def soak_log_entry(soak: SoakState, *, step: int, setpoint_c: float, start_t_s: float,
                   end_t_s: float, soak_s: float, held_s: float, edge: bool,
                   resumed: bool) -> dict[str, Any]:
    """The step log's record of one finished soak (its last decision, the rate gain used)."""
    used = [g for g in soak.gains.values() if g is not None]
    decision = soak.decision
    return {
        "step": step, "setpoint_c": setpoint_c, "soak_start_t_s": start_t_s,
        "soak_end_t_s": end_t_s, "soak_s": soak_s, "held_s": held_s,
        "reason": decision.reason, "tau_s": decision.tau_s,
        "predicted_offset_c": decision.predicted_offset_c,
        "predicted_error_c": decision.predicted_error_c,
        "die_rate_c_per_min": decision.die_rate_c_per_min, "sweep_s": soak.sweep_s,
        "edge": edge, "policy": soak.cfg.policy,
        "resumed": resumed, "max_soak_reached": decision.max_soak_reached,
        # the k (µg per °C/min) the last decision used, largest over the sensors
        "rate_gain_ug_per_c_per_min": max(used) if used else None,
    }


def clean_json(d: Mapping[str, Any]) -> dict[str, Any]:
    """Non-finite floats as None (JSON has no NaN)."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in d.items()}


# --- the dies against the chamber ----------------------------------------------------------
def die_track_of(dies: Mapping[str, list[rate_gain.Probe]]) -> DieTrack | None:
    """The dies' last reading from a soak's probes (the latest probe's time, the median of
    each die's last temperature); None without probes."""
    last = [probes[-1] for probes in dies.values() if probes]
    if not last:
        return None
    return (max(p.clock_s for p in last), float(np.median([p.sensor_c for p in last])))


def die_against_chamber(before: DieTrack | None, now_s: float, dies_c: Sequence[float],
                        process_c: float, pv_before: DieTrack | None = None
                        ) -> tuple[DieTrack | None, str | None]:
    """Do the dies (``dies_c``, °C, one per live sensor) agree with the chamber's PV?
    Returns the new track and None, or why not (DESIGN: plausibility at the boundaries).

    The median die more than :data:`DIE_PV_TOLERANCE_C` from the PV is a die still
    approaching the air (a short soak: it moves towards the PV at about gap/τ) or a
    chamber read wrong (a map's decimal places, °F, an offset: the die has settled, far
    from what the PV says). The second would label every capture of the step with a
    wrong temperature. A die moving towards the PV fast enough for a lag of at most
    :data:`DIE_LAG_TAU_MAX_S` is a lag. Sensors without a temperature channel (non-finite
    ``dies_c``) say nothing and keep ``before``; the first reading with nothing before it
    only starts the track.

    ``pv_before``: the PV at the previous capture (clock s, °C; None after a soak, where
    the air stood at its setpoint), for how fast the PV itself moves (a ramp campaign's
    chamber never stops). A die lags a moving air by up to that rate times its time
    constant, and at a turn of the ramp a die behind a fixture still moves the old way
    while the gap grows:
    a gap within :data:`DIE_PV_TOLERANCE_C` plus |rate| × :data:`DIE_LAG_TAU_MAX_S` is
    lag. A ×10 scale or a unit error on a steady PV is still refused.
    """
    dies = [float(c) for c in dies_c if math.isfinite(float(c))]
    if not dies or not math.isfinite(process_c):
        return before, None
    die_c = float(np.median(dies))
    track = (now_s, die_c)
    gap_c = process_c - die_c
    lag_c = 0.0
    if pv_before is not None and now_s > pv_before[0] and math.isfinite(pv_before[1]):
        lag_c = abs(_rate_c_per_s(pv_before, now_s, process_c)) * DIE_LAG_TAU_MAX_S
    if abs(gap_c) <= DIE_PV_TOLERANCE_C + lag_c or before is None or now_s <= before[0]:
        return track, None
    rate_c_per_s = _rate_c_per_s(before, now_s, die_c)
    if gap_c * rate_c_per_s > 0 and abs(rate_c_per_s) * DIE_LAG_TAU_MAX_S >= abs(gap_c):
        return track, None  # still approaching the air: a lag, not a mis-read chamber
    return track, (
        f"the chamber reads {process_c:.1f} °C while the sensors' dies read {die_c:.1f} °C "
        f"and are not approaching it ({rate_c_per_s * 60:+.2f} °C/min); this capture was "
        "not stored: the chamber's temperature is likely read with a wrong scale (decimal "
        "places), unit (°F, K) or offset in its register map — `soakcal rig check RIG` "
        "names the map key to fix")


def _rate_c_per_s(before: DieTrack, now_s: float, now_c: float) -> float:
    """°C/s from the reading ``before`` (clock s, °C) to ``now_c`` at ``now_s``."""
    return (now_c - before[1]) / (now_s - before[0])
