"""The campaign spec (the validated POST body) as the engine reads it, with defaults.

The API validates the contract fields (rig, sensor, setpoints_c, soak_min,
positions, samples_per_position); the engine tolerates extra keys that tune
its behaviour (stability policy, tolerances, fault limits). Unknown keys are
ignored so the API may add fields freely.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service.engine.quality import QualityLimits
from service.engine.stability import (
    DEFAULT_DRIFT_BUDGET,
    DEFAULT_EDGE_TOL_C,
    DEFAULT_GRADIENT_LAG_S,
    DEFAULT_STEP_TOL_C,
    DEFAULT_TEMPCO_UG_PER_C,
    StabilityConfig,
    temperature_budget_c,
)

# RunSpec fields a campaign may set directly (typed like their defaults).
RUN_TUNING_KEYS = (
    "ramp_c_per_min", "soak_poll_s", "soak_probe_samples", "settle_s", "safe_c", "range_g",
    "odr_hz", "retry_attempts", "retry_backoff_s", "suspend_poll_s", "suspend_limit_s",
    "move_timeout_s",
)
# Every optional key parse_spec reads besides the API contract's fields: the API lets
# exactly these through and rejects other extras as typos (service/api/schemas.py).
TUNING_KEYS = frozenset({
    "stability", "min_soak_min", "max_soak_min", "tol_c", "dwell_min", "die_tol_c",
    "expected_sd_g", "max_span_c", "temp_noise_c", "on_max_soak", "temp_budget_c",
    "tempco_ug_per_c", "drift_budget", "gradient_lag_s", "step_tol_c", "edge_tol_c",
    *RUN_TUNING_KEYS,
})

DEFAULT_SETPOINTS_C = [-40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0]


@dataclass(frozen=True)
class RunSpec:
    setpoints_c: list[float]
    positions: str
    samples_per_position: int
    stability: StabilityConfig
    quality: QualityLimits
    on_max_soak: str = "continue"  # continue | fail
    ramp_c_per_min: float = 1.0
    soak_poll_s: float = 60.0  # cheap sensor/chamber poll period during a soak
    soak_probe_samples: int = 8  # samples per cheap die-temperature probe
    settle_s: float = 5.0  # wait after in-position before acquiring (table ringing)
    move_timeout_s: float = 120.0
    safe_c: float = 23.0  # abort leaves the chamber here
    range_g: float = 2.0
    odr_hz: float = 62.5
    retry_attempts: int = 4  # tries of one device call before the campaign suspends
    retry_backoff_s: float = 1.0  # first back-off, doubled each try
    suspend_poll_s: float = 30.0
    suspend_limit_s: float = 1800.0  # suspended longer than this: fail the campaign
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return len(self.setpoints_c)


def parse_spec(spec: dict[str, Any]) -> RunSpec:
    """A :class:`RunSpec` from a campaign's JSON spec (defaults = the seed's protocol)."""
    soak_s = float(spec.get("soak_min", 60.0)) * 60.0
    policy = str(spec.get("stability", "predictive"))
    quality = QualityLimits(
        expected_sd_g=float(spec.get("expected_sd_g", QualityLimits.expected_sd_g)),
        max_span_c=float(spec.get("max_span_c", QualityLimits.max_span_c)),
        temp_noise_c=float(spec.get("temp_noise_c", QualityLimits.temp_noise_c)),
    )
    samples = int(spec.get("samples_per_position", 200))
    die_tol = spec.get("die_tol_c")
    stab = StabilityConfig(
        policy=policy,
        soak_s=soak_s,
        min_soak_s=float(spec.get("min_soak_min", min(10.0, soak_s / 60.0))) * 60.0,
        max_soak_s=float(spec.get("max_soak_min", 2.0 * soak_s / 60.0)) * 60.0,
        tol_c=float(spec.get("tol_c", 0.3)),
        dwell_s=float(spec.get("dwell_min", min(5.0, soak_s / 60.0))) * 60.0,
        # What the thermal model can absorb: a fraction of one reading's noise over the
        # sensor's tempco (docs/engine.md, "Stability decision").
        temp_budget_c=float(spec.get("temp_budget_c", temperature_budget_c(
            quality.expected_sd_g / max(samples, 1) ** 0.5,
            float(spec.get("tempco_ug_per_c", DEFAULT_TEMPCO_UG_PER_C)),
            float(spec.get("drift_budget", DEFAULT_DRIFT_BUDGET))))),
        gradient_lag_s=float(spec.get("gradient_lag_s", DEFAULT_GRADIENT_LAG_S)),
        step_tol_c=float(spec.get("step_tol_c", DEFAULT_STEP_TOL_C)),
        edge_tol_c=float(spec.get("edge_tol_c", DEFAULT_EDGE_TOL_C)),
        die_tol_c=None if die_tol is None else float(die_tol),
    )
    on_max = str(spec.get("on_max_soak", "continue"))
    if on_max not in ("continue", "fail"):
        raise ValueError(f"on_max_soak must be 'continue' or 'fail', got {on_max!r}")
    keys = RUN_TUNING_KEYS
    tuned = {k: type(getattr(RunSpec, k, 0.0))(spec[k]) for k in keys if k in spec}
    return RunSpec(
        setpoints_c=[float(v) for v in spec.get("setpoints_c", DEFAULT_SETPOINTS_C)],
        positions=str(spec.get("positions", "table1")),
        samples_per_position=samples,
        stability=stab,
        quality=quality,
        on_max_soak=on_max,
        extra={k: v for k, v in spec.items() if k not in keys},
        **tuned,
    )


def schedule_refs(name: str) -> np.ndarray:
    """Unit gravity references (n, 3) of a named schedule (the calibration core owns them)."""
    from calibration.schedules import get_schedule

    return np.asarray(get_schedule(name), float)
