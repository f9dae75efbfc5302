"""Put the winning terms into the twin's sensor model (``simulators/effects.py``).

``to_truth_effects(diagnosis)`` maps each finding to the Effect object whose
constructor parameters are the same physics in g-based units, so that a
simulation of the same campaign with ``SensorTruth(effects=...)`` matches.
``thermal_lag`` maps to :class:`simulators.effects.ThermalLag` (rig physics:
pass ``eff.physics(RigPhysics())`` and record ``chamber_c``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from simulators import effects as sim

AX = ("x", "y", "z")


def to_truth_effects(diagnosis: Any) -> list[Any]:
    out: list[Any] = []
    for f in diagnosis.findings:
        p = f.parameters
        e = f.effect
        if e == "scale_nonlinearity":
            out.append(sim.ScaleNonlinearity(
                k2_per_g=np.array([p[f"k2_{a}_ug_per_g2"] for a in AX]) * 1e-6,
                k3_per_g2=np.array([p[f"k3_{a}_ug_per_g3"] for a in AX]) * 1e-6))
        elif e == "thermal_hysteresis":
            out.append(sim.ThermalHysteresis(h_g=np.array([p[f"h_{a}_ug"] for a in AX]) * 1e-6))
        elif e == "bias_drift":
            out.append(sim.BiasDrift(
                rate_g_per_h=np.array([p[f"rate_{a}_ug_per_h"] for a in AX]) * 1e-6))
        elif e == "thermal_lag":
            out.append(sim.ThermalLag(tau_s=float(p["tau_s"])))
        elif e == "cross_coupling":
            out.append(sim.CrossCoupling(**{f"k_{q}_per_g": p[f"k_{q}_ug_per_g2"] * 1e-6
                                            for q in ("xy", "xz", "yz")}))
        elif e == "temperature_rate":
            # ours per °C/min of the recorded slope, theirs per °C/s of the die rate
            out.append(sim.TemperatureRate(k_g_per_c_per_s=np.array(
                [p[f"k_rate_{a}_ug_per_c_per_min"] for a in AX]) * 1e-6 * 60.0))
        elif e == "vibration_rectification":
            out.append(sim.VibrationRectification(
                c_per_g=np.array([p[f"c_{a}_per_g"] for a in AX])))
        elif e == "session_offset":
            off = np.array([p[f"offset_{a}_ug"] for a in AX]) * 1e-6
            out.append(sim.SessionOffset(offsets_g=np.vstack([np.zeros(3), off])))
        elif e == "outlier":
            rows = tuple(int(r) for r in f.rows)
            out.append(sim.Outlier(size_g=np.array([p.get(f"size_{a}_ug", 0.0) for a in AX])
                                   * 1e-6, rows=rows))
    return out
