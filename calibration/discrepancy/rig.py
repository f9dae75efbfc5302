"""The rig's thermal physics shared by the twin and the diagnosis: setpoint → air → die.

A campaign records the air (``chamber_c``) only on the plateaus; the die's temperature at
a reading depends on the history in between. The history is reconstructed from the
recording's plateaus: the working setpoint ramps at ``ramp_c_per_min`` between plateaus
(starting after the previous plateau's last reading; the first plateau is reached from
``AMBIENT_C`` after a soak as long as the others'), the air follows the working setpoint
through a first-order lag ``air_tau_s`` (the chamber's response) and the die follows the
air through ``die_tau_s``. Both lags are integrated exactly for a piecewise-constant input
on a ``DT_S`` grid. The plant's steps and the ramp reconstruction are
``calibration.thermal_plant``'s: the same cascade ``simulators.campaign_sim`` runs and the
same history the ``thermal_lag`` effect lags behind, so a twin's lag means the same thing
in the simulator and in ``diagnose --against``.
"""

from __future__ import annotations

import numpy as np

from calibration.thermal_plant import (
    AMBIENT_C,
    DEFAULT_AIR_TAU_S,
    DEFAULT_RAMP_C_PER_MIN,
    lag_series,
    ramp_breakpoints,
)

DT_S = 2.0


def die_minus_air_c(t_s: np.ndarray, steps: np.ndarray, step_temp_c: dict[int, float],
                    die_tau_s: float, air_tau_s: float = DEFAULT_AIR_TAU_S,
                    ramp_c_per_min: float = DEFAULT_RAMP_C_PER_MIN) -> np.ndarray:
    """T_die − T_air (°C) at each reading for the reconstructed history (module docstring)."""
    if die_tau_s <= 0:
        return np.zeros(t_s.size)
    grid, setpoint = setpoint_history(t_s, steps, step_temp_c, ramp_c_per_min)
    air = lag_series(setpoint, DT_S, air_tau_s)
    die = lag_series(air, DT_S, die_tau_s)
    return np.interp(t_s, grid, die - air)


def setpoint_history(t_s: np.ndarray, steps: np.ndarray, step_temp_c: dict[int, float],
                     ramp_c_per_min: float) -> tuple[np.ndarray, np.ndarray]:
    """The working setpoint on a ``DT_S`` grid covering the campaign (times, °C)."""
    bt, bv = ramp_breakpoints(t_s, steps, step_temp_c, ramp_c_per_min, AMBIENT_C)
    end = max(float(t_s.max()), float(bt[-1])) + DT_S
    grid = np.arange(bt[0], end + DT_S, DT_S)
    return grid, np.interp(grid, bt, bv)
