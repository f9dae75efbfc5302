"""Concealable effects for the blind benchmark: one magnitude ``m`` scales a drawn pattern.

``make(effect_id, m, pattern, protocol, n_rows)`` returns the truth-model effect
(``simulators/effects.py``) and its parameters named with units (the answer
key). ``pattern`` is drawn once per case by :func:`draw_pattern` (signs, axes,
rows), so λ(m) is exactly linear in ``m`` for every additive effect and the
minimum detectable size can be scaled; ``thermal_lag`` (m = τ in s) is not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.blind.protocols import Protocol
from simulators import effects as fx

UNIT = {
    "thermal_lag": "s (die time constant τ)",
    "thermal_hysteresis": "µg (h per axis, largest)",
    "scale_nonlinearity": "µg/g² (K2, K3 largest)",
    "cross_coupling": "µg/g² (per pair, largest)",
    "bias_drift": "µg/h (largest axis)",
    "session_offset": "µg (largest axis)",
    "outlier": "µg (per disturbed reading, largest axis)",
    "vibration_rectification": "µg (offset at the cold-end vibration)",
    "temperature_sensor": "°C (glitch size)",
    "self_heating": "°C (die above chamber)",
    "turntable_geometry": "µrad (base tilt, largest)",
    "temperature_rate": "µg per °C/min",
    "local_gravity": "ppm (g_local − 1)",
    "lever_arm": "mm",
    "filter_delay": "ms",
}
NONLINEAR = {"thermal_lag"}
DF = {  # free parameters of the compact model a diagnoser fits
    "thermal_lag": 1, "thermal_hysteresis": 3, "scale_nonlinearity": 6, "cross_coupling": 3,
    "bias_drift": 3, "session_offset": 3, "outlier": 1, "vibration_rectification": 3,
    "temperature_sensor": 1, "self_heating": 2, "turntable_geometry": 2,
    "temperature_rate": 3, "local_gravity": 1, "lever_arm": 3, "filter_delay": 1,
}


# Effects on a few unknown readings: dof of the per-reading test (the rows are searched).
# outlier: a reading off by an unknown 3-vector; glitch: the temperature of a reading off,
# its direction in the output known from the model (∂raw/∂T), so one dof.
ROWWISE = {"outlier": 3, "temperature_sensor": 1}


@dataclass
class Concealed:
    effect: Any  # an Effect, or fx.ThermalLag (rig physics)
    parameters: dict[str, Any]


def draw_pattern(rng: np.random.Generator, protocol: Protocol, n_rows: int) -> dict[str, Any]:
    """Signs/relative sizes per axis (largest = 1) and rows for row-wise effects."""
    def unit3() -> np.ndarray:
        v = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.3, 1.0, 3)
        return v / np.abs(v).max()

    n_pos = protocol.refs().shape[0]
    steps = rng.choice(np.arange(1, len(protocol.setpoints_c) - 1), 2, replace=False)
    rows = [int(s * n_pos + rng.integers(n_pos)) for s in steps]
    return {"a": unit3(), "b": unit3(), "c": unit3(), "rows": sorted(rows),
            "tilt": unit3()[:2]}


def make(effect_id: str, m: float, pat: dict[str, Any], protocol: Protocol) -> Concealed:
    a, b = pat["a"], pat["b"]
    u = 1e-6 * m
    if effect_id == "thermal_lag":
        return Concealed(fx.ThermalLag(tau_s=m), {"tau_s": m})
    if effect_id == "thermal_hysteresis":
        return Concealed(fx.ThermalHysteresis(h_g=u * a), {"h_g": list(u * a)})
    if effect_id == "scale_nonlinearity":
        return Concealed(fx.ScaleNonlinearity(k2_per_g=u * a, k3_per_g2=u * b),
                         {"k2_per_g": list(u * a), "k3_per_g2": list(u * b)})
    if effect_id == "cross_coupling":
        k = u * a
        return Concealed(fx.CrossCoupling(*k), {"k_xy_per_g": k[0], "k_xz_per_g": k[1],
                                                "k_yz_per_g": k[2]})
    if effect_id == "bias_drift":
        return Concealed(fx.BiasDrift(rate_g_per_h=u * a), {"rate_g_per_h": list(u * a)})
    if effect_id == "session_offset":
        off = np.vstack([np.zeros(3), u * a])
        return Concealed(fx.SessionOffset(offsets_g=off), {"offsets_g": off.tolist()})
    if effect_id == "outlier":
        return Concealed(fx.Outlier(size_g=u * a, rows=tuple(pat["rows"])),
                         {"size_g": list(u * a), "rows": pat["rows"]})
    if effect_id == "vibration_rectification":
        c = u * a / max(protocol.vib_cold_sd_g, 1e-4) ** 2
        return Concealed(fx.VibrationRectification(c_per_g=c), {"c_per_g": list(c)})
    if effect_id == "temperature_sensor":
        return Concealed(fx.TemperatureSensor(glitch_c=m, glitch_rows=tuple(pat["rows"])),
                         {"glitch_c": m, "glitch_rows": pat["rows"]})
    if effect_id == "self_heating":
        return Concealed(fx.SelfHeating(delta_c=m, warmup_tau_s=1800.0),
                         {"delta_c": m, "warmup_tau_s": 1800.0})
    if effect_id == "turntable_geometry":
        t = u * pat["tilt"]
        return Concealed(fx.TurntableGeometry(base_tilt_rad=t), {"base_tilt_rad": list(t)})
    if effect_id == "temperature_rate":
        k = u * a * 60.0
        return Concealed(fx.TemperatureRate(k_g_per_c_per_s=k), {"k_g_per_c_per_s": list(k)})
    if effect_id == "local_gravity":
        return Concealed(fx.LocalGravity(g_local=1.0 + u), {"g_local": 1.0 + u})
    if effect_id == "lever_arm":
        r = 1e-3 * m * a
        return Concealed(fx.LeverArm(r_m=r), {"r_m": list(r)})
    if effect_id == "filter_delay":
        return Concealed(fx.FilterDelay(delay_s=1e-3 * m), {"delay_s": 1e-3 * m})
    raise ValueError(f"unknown effect id {effect_id!r}")
