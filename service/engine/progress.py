"""ETA of a running campaign: what is left × what things have been taking.

eta = remaining positions × measured time per position
    + remaining soak of the current step (if soaking)
    + remaining steps × (expected ramp + expected soak).
Expected values start from the spec (ramp at the commanded rate between
setpoints, the nominal soak) and are replaced by running means as the
campaign measures them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from service.engine.spec import RunSpec

# Before the first position is measured: move + settle + 200 samples at 62.5 Hz ≈ 15 s.
DEFAULT_POSITION_S = 15.0


@dataclass
class EtaModel:
    n_steps: int
    n_positions: int
    n_done: int
    ramp_s: float  # expected ramp time per step
    soak_s: float  # expected soak time per step
    position_times_s: list[float] = field(default_factory=list)
    soak_times_s: list[float] = field(default_factory=list)
    ramp_times_s: list[float] = field(default_factory=list)

    @classmethod
    def for_spec(cls, spec: RunSpec, n_positions: int, n_done: int = 0) -> EtaModel:
        sp = spec.setpoints_c
        deltas = [abs(b - a) for a, b in zip(sp, sp[1:], strict=False)] or [0.0]
        ramp_s = sum(deltas) / len(deltas) / max(spec.ramp_c_per_min, 0.05) * 60.0
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

    @property
    def position_s(self) -> float:
        recent = self.position_times_s[-24:]
        return sum(recent) / len(recent) if recent else DEFAULT_POSITION_S

    def eta_s(self, step: int, phase: str, soak_remaining_s: float | None = None) -> float:
        remaining_positions = self.n_steps * self.n_positions - self.n_done
        steps_after = max(0, self.n_steps - step - 1)
        eta = remaining_positions * self.position_s + steps_after * (self.ramp_s + self.soak_s)
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
