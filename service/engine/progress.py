"""ETA of a running campaign: what is left × what things have been taking.

eta = remaining positions × measured time per position
    + remaining soak of the current step (if soaking)
    + remaining steps × (expected ramp + expected soak).
Expected values start from the spec (the ramp at the rate the air moves between
setpoints, the nominal soak) and are replaced by running means as the campaign
measures them. That rate is the chamber's moving rate
(:func:`drivers.ramp_rule.moving_rate_c_per_min`: the commanded ramp, or on a step,
``ramp_c_per_min = 0``, the chamber's own rate). When it is not known the ramps'
time is undetermined and so is the ETA (``None``), until the first ramp is measured:
never a made-up rate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drivers.ramp_rule import RampControl, moving_rate_c_per_min
from service.engine.spec import RunSpec

# Before the first position is measured: move + settle + 200 samples at 62.5 Hz ≈ 15 s.
DEFAULT_POSITION_S = 15.0
#: The slowest air the engine assumes when the commanded rate is below it (°C/min).
SLOWEST_RATE_C_PER_MIN = 0.05


def chamber_moving_rate_c_per_min(chamber: Any, ramp_c_per_min: float) -> float | None:
    """The rate (°C/min) the rig's air moves between setpoints: the rule's moving rate
    (:func:`drivers.ramp_rule.moving_rate_c_per_min`) of the chamber driver's
    ``ramp_control``; a driver without one: the commanded rate (> 0), else ``None``."""
    ctrl = getattr(chamber, "ramp_control", None)
    if isinstance(ctrl, RampControl):
        return moving_rate_c_per_min(ctrl, ramp_c_per_min)
    return float(ramp_c_per_min) if ramp_c_per_min > 0 else None


@dataclass
class EtaModel:
    n_steps: int
    n_positions: int
    n_done: int
    ramp_s: float | None  # expected ramp time per step; None: not known yet
    soak_s: float  # expected soak time per step
    position_times_s: list[float] = field(default_factory=list)
    soak_times_s: list[float] = field(default_factory=list)
    ramp_times_s: list[float] = field(default_factory=list)

    @classmethod
    def for_spec(cls, spec: RunSpec, n_positions: int, n_done: int = 0,
                 rate_c_per_min: float | None = None) -> EtaModel:
        """The model before anything is measured. ``rate_c_per_min``: the rate the air moves
        between setpoints (the rule's moving rate); None: the spec's ``ramp_c_per_min``
        when it commands one (> 0), else not known (a step at an unstated rate)."""
        sp = spec.setpoints_c
        deltas = [abs(b - a) for a, b in zip(sp, sp[1:], strict=False)] or [0.0]
        mean_delta_c = sum(deltas) / len(deltas)
        ramp_s: float | None = None
        if rate_c_per_min is not None and rate_c_per_min > 0:
            ramp_s = mean_delta_c / float(rate_c_per_min) * 60.0
        elif spec.ramp_c_per_min > 0:  # the commanded ramp (the floor as it always was)
            ramp_s = mean_delta_c / max(spec.ramp_c_per_min, 0.05) * 60.0
        soak_s = spec.stability.soak_s if spec.stability.policy != "predictive" else (
            0.75 * spec.stability.soak_s)
        return cls(spec.n_steps, n_positions, n_done, ramp_s, soak_s)

    def position_done(self, dt_s: float) -> None:
        self.n_done += 1
        self.position_times_s.append(dt_s)

    def soak_done(self, dt_s: float) -> None:
        self.soak_times_s.append(dt_s)
        self.soak_s = sum(self.soak_times_s) / len(self.soak_times_s)

    def ramp_done(self, dt_s: float) -> None:
        self.ramp_times_s.append(dt_s)
        self.ramp_s = sum(self.ramp_times_s) / len(self.ramp_times_s)

    @property
    def position_s(self) -> float:
        recent = self.position_times_s[-24:]
        return sum(recent) / len(recent) if recent else DEFAULT_POSITION_S

    def eta_s(self, step: int, phase: str,
              soak_remaining_s: float | None = None) -> float | None:
        """Seconds of rig time left; ``None`` while a ramp is still to come and its time is
        not known (:meth:`for_spec` had no rate and none has been measured)."""
        remaining_positions = self.n_steps * self.n_positions - self.n_done
        steps_after = max(0, self.n_steps - step - 1)
        if steps_after and self.ramp_s is None:
            return None
        ramp_s = self.ramp_s or 0.0  # only read when no ramp is left, or known
        eta = remaining_positions * self.position_s + steps_after * (ramp_s + self.soak_s)
        if phase == "ramp":
            eta += self.soak_s
        elif phase == "soak" and soak_remaining_s is not None:
            eta += soak_remaining_s
        return max(0.0, eta)


Subscriber = Callable[[Any, float, float], None]


class EtaSubscriber:
    """Keeps an :class:`EtaModel` current from the plan's message stream.

    Called with (message, started_s, ended_s) for each message the engine has
    executed: a ramp's duration from its ``SetChamber`` to its ``WaitChamber``, a
    soak's from ``WaitStable`` (a resumed step's short re-check is not a soak), a
    position's from its ``Move`` to its ``Save``.
    """

    def __init__(self, eta: EtaModel) -> None:
        self.eta = eta
        self._position_start_s: float | None = None
        self._ramp_start_s: float | None = None

    def __call__(self, msg: Any, started_s: float, ended_s: float) -> None:
        from calibration import campaign_plan as plan

        if isinstance(msg, plan.SetChamber):
            self._ramp_start_s = started_s
        elif isinstance(msg, plan.WaitChamber) and self._ramp_start_s is not None:
            self.eta.ramp_done(ended_s - self._ramp_start_s)
            self._ramp_start_s = None
        elif isinstance(msg, plan.WaitStable) and not msg.resumed:
            self.eta.soak_done(ended_s - started_s)
        elif isinstance(msg, plan.Move):
            self._position_start_s = started_s
        elif isinstance(msg, plan.Save) and self._position_start_s is not None:
            self.eta.position_done(ended_s - self._position_start_s)
            self._position_start_s = None
