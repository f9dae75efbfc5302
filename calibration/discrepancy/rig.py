"""The rig's thermal physics shared by the twin and the diagnosis: setpoint → air → die.

A campaign records the air (``chamber_c``) only on the plateaus; the die's temperature at
a reading depends on the history in between. The history is reconstructed from the
recording's plateaus: the working setpoint ramps at ``ramp_c_per_min`` between plateaus
(starting after the previous plateau's last reading; the first plateau is reached from
``AMBIENT_C`` after a soak as long as the others'), the air follows the working setpoint
through a first-order lag ``air_tau_s`` (the chamber's response) and the die follows the
air through ``die_tau_s``. Both lags are integrated exactly for a piecewise-constant input
on a ``DT_S`` grid. The same cascade is what ``simulators.campaign_sim`` runs, so a twin's
lag means the same thing in the simulator and in ``diagnose --against``.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

AMBIENT_C = 25.0
DT_S = 2.0
DEFAULT_AIR_TAU_S = 120.0  # the offline rig's air settling (simulators.campaign_sim.RigPhysics)
DEFAULT_RAMP_C_PER_MIN = 2.0


def die_minus_air_c(t_s: np.ndarray, steps: np.ndarray, step_temp_c: dict[int, float],
                    die_tau_s: float, air_tau_s: float = DEFAULT_AIR_TAU_S,
                    ramp_c_per_min: float = DEFAULT_RAMP_C_PER_MIN) -> np.ndarray:
    """T_die − T_air (°C) at each reading for the reconstructed history (module docstring)."""
    if die_tau_s <= 0:
        return np.zeros(t_s.size)
    grid, setpoint = setpoint_history(t_s, steps, step_temp_c, ramp_c_per_min)
    air = _first_order(setpoint, air_tau_s)
    die = _first_order(air, die_tau_s)
    return np.interp(t_s, grid, die - air)


def setpoint_history(t_s: np.ndarray, steps: np.ndarray, step_temp_c: dict[int, float],
                     ramp_c_per_min: float) -> tuple[np.ndarray, np.ndarray]:
    """The working setpoint on a ``DT_S`` grid covering the campaign (times, °C)."""
    ids = sorted(step_temp_c)
    first = {s: float(t_s[steps == s].min()) for s in ids}
    last = {s: float(t_s[steps == s].max()) for s in ids}
    rate = ramp_c_per_min / 60.0
    temp = [step_temp_c[s] for s in ids]
    soaks = [first[ids[k]] - last[ids[k - 1]] - abs(temp[k] - temp[k - 1]) / rate
             for k in range(1, len(ids))]
    soak = max(float(np.median(soaks)), 0.0) if soaks else 0.0
    t0 = first[ids[0]] - soak - abs(temp[0] - AMBIENT_C) / rate
    bt, bv = [t0, t0 + abs(temp[0] - AMBIENT_C) / rate], [AMBIENT_C, temp[0]]
    for k in range(1, len(ids)):
        start = max(last[ids[k - 1]], bt[-1])
        bt += [start, start + abs(temp[k] - temp[k - 1]) / rate]
        bv += [temp[k - 1], temp[k]]
    end = max(float(t_s.max()), bt[-1]) + DT_S
    grid = np.arange(bt[0], end + DT_S, DT_S)
    return grid, np.interp(grid, bt, bv)


def _first_order(u: np.ndarray, tau_s: float) -> np.ndarray:
    """y' = (u − y)/τ, y(0) = u(0), exact for u constant over each ``DT_S``."""
    if tau_s <= 0:
        return u.copy()
    a = float(np.exp(-DT_S / tau_s))
    y, _ = lfilter([1.0 - a], [1.0, -a], u, zi=[a * u[0]])
    return y
