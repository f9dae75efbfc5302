"""One rule for a commanded ramp rate, whatever the chamber's protocol.

A chamber either *controls* its ramp (a static ramp register, or a write sequence
that sets one) or it does not: it steps to each setpoint and the air moves at the
chamber's own rate (a CSZ EZT-430i, a legacy Watlow F4, an ESPEC P-300/SCP-220 in
constant mode). ``ramp_c_per_min = 0`` in a campaign means *step*: the chamber
moves at its own rate. For a soak campaign that is enough: the soak, not the ramp
between steps, decides when the die is stable and what is measured.

* A chamber that cannot control its ramp accepts 0 (nothing is written to a ramp
  it does not have) and a rate at or above its own fastest rate (stepping then
  moves the air no faster than asked: the commanded ramp is a limit the chamber
  honours without being told). A slower rate is refused, naming the fix (0); when
  the chamber's own rate is not stated, only 0 is accepted.
* A chamber that controls its ramp takes a rate > 0. It accepts 0 only where its
  description says the register's 0 means "no ramp" (step); no shipped map states
  it, so 0 is refused naming the map: on a register whose 0 is unstated, 0 may
  mean "no limit" or "a ramp of zero" that never reaches the setpoint.

Both chamber drivers (:mod:`drivers.chamber`, :mod:`drivers.espec_chamber`) and the
service's dry run (``service/dry_run.py``) apply :func:`ramp_refusal`, so the
refusal reads the same at the door and at the wire.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.registermaps import ChamberMap

#: ``ramp_c_per_min`` meaning "step: the chamber moves at its own rate".
STEP_C_PER_MIN = 0.0


@dataclass(frozen=True)
class RampControl:
    """What one chamber can do with a commanded ramp rate."""

    controller: str  # who, as a person reads it: "map csz-ezt-430i", "an ESPEC P-300/SCP-220"
    controlled: bool  # it has a ramp to set (a register or a set_ramp_rate sequence)
    # Why it has no ramp (controlled False), or why its 0 cannot mean "step" (controlled True).
    why: str
    own_rate_c_per_min: float | None = None  # the chamber's fastest rate; None: not stated
    rate_key: str = "chamber.max_rate_c_per_min"  # where that rate is stated
    zero_is_step: bool = False  # a controlled ramp whose register's 0 means "no ramp"


def ramp_refusal(ctrl: RampControl, ramp_c_per_min: float) -> str | None:
    """``None`` when ``ctrl``'s chamber honours ``ramp_c_per_min`` (module docstring),
    else why not and the fix, in one sentence."""
    rate = float(ramp_c_per_min)
    if ctrl.controlled:
        if rate > 0 or ctrl.zero_is_step:
            return None
        return (f"ramp rate 0 °C/min (step) cannot be commanded: {ctrl.controller} has a "
                f"ramp register and {ctrl.why}; run the campaign with ramp_c_per_min > 0")
    own = ctrl.own_rate_c_per_min
    if rate == STEP_C_PER_MIN or (own is not None and rate >= own):
        return None
    stated = (f" (up to {own:g} °C/min, {ctrl.rate_key})" if own is not None
              else f", which is not stated ({ctrl.rate_key})")
    also = f" or ≥ {own:g}" if own is not None else ""
    return (f"ramp rate {rate:g} °C/min cannot be commanded: {ctrl.controller} has no "
            f"static ramp ({ctrl.why}) and steps to each setpoint at the chamber's own "
            f"rate{stated}; run the campaign with ramp_c_per_min = 0 (step){also}")


def moving_rate_c_per_min(ctrl: RampControl, ramp_c_per_min: float) -> float | None:
    """The rate the air is expected to move at between setpoints, °C/min: the commanded
    ramp on a chamber that controls it (> 0), else (a step) the chamber's own rate;
    ``None`` when that rate is not stated (never a made-up rate)."""
    if ctrl.controlled and ramp_c_per_min > 0:
        return float(ramp_c_per_min)
    return ctrl.own_rate_c_per_min


def ramp_method_refusal(ctrl: RampControl) -> str | None:
    """``None`` when ``ctrl``'s chamber can run a ``method: "ramp"`` campaign (a controlled
    ramp through the setpoints' range), else why not and the fix."""
    if ctrl.controlled:
        return None
    return (f"method 'ramp' needs a controlled ramp: {ctrl.controller} has no static ramp "
            f"({ctrl.why}); run it as a soak campaign (method 'soak', ramp_c_per_min = 0)")


def map_ramp_control(regmap: ChamberMap,
                     max_rate_c_per_min: float | None = None) -> RampControl:
    """The :class:`RampControl` of a register map's controller. The chamber's own rate is
    the rig's ``chamber.max_rate_c_per_min`` when given, else the map's
    ``limits.max_ramp_c_per_min``."""
    name, limit = regmap.name, regmap.max_ramp_c_per_min
    own, key = ((float(max_rate_c_per_min), "chamber.max_rate_c_per_min")
                if max_rate_c_per_min is not None else
                (None if limit is None else float(limit),
                 f"chamber.max_rate_c_per_min, or limits.max_ramp_c_per_min of map {name}"))
    if regmap.ramp_field() is None:
        return RampControl(f"map {name}", False,
                           "the map lists ramp_c_per_min under absent_roles", own, key)
    return RampControl(f"map {name}", True,
                       "does not state that the register's 0 means 'no ramp' (0 may be no "
                       "limit, or a ramp of zero that never reaches the setpoint)", own, key)
