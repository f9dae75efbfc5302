"""The rig's thermal plant, written once: setpoint → chamber air → sensor die.

The seed paper's thermal model (Eq. 8) gives the SFEM parameters as polynomials of the
temperature the sensor *is at*; the chamber only controls its air (ramped at 0.1–5 °C/min,
seed Table 3). What stands between them is this plant, used by the offline twin
(``simulators.campaign_sim``), the Modbus twin (``simulators.chamber_sim``), the twin's
rig reconstruction (``calibration.discrepancy.rig``) and the ``thermal_lag`` effect
(``calibration.discrepancy.effects.thermal_lag``):

* the working setpoint moves towards the setpoint no faster than the ramp-rate limit
  (:func:`rate_limited`);
* the air follows the working setpoint, and the die follows the air, each as a
  first-order lag ``y' = (u − y)/τ``. For an input held constant over a step ``dt``
  the step is exact: ``y ← u + (y − u)·e^{−dt/τ}`` (:func:`lag_step`; the same
  recurrence over a uniform grid: :func:`lag_series`);
* for an input that is piecewise *linear* (the ramps and plateaus reconstructed from a
  recording's plateaus, :func:`ramp_breakpoints`), the lag ``δ = y − u`` has a closed
  form per segment (:func:`lag_behind_piecewise_linear`).

Pure numerics: no clock, no state. ``τ ≤ 0`` means no lag (the output is the input).
What each twin drives the die with is its own choice and stays so: the offline twin the
air at the end of each step, the Modbus twin the mean air of each substep (it also caps
the air's rate and relaxes to ambient when stopped).
"""

from __future__ import annotations

import math

import numpy as np

# The offline rig's defaults (simulators.campaign_sim.RigPhysics), which are also what the
# diagnosis assumes where a recording does not say (it holds the plateaus, not the ramps).
# The lab's ambient, the one value: the rig (air and die) before the first ramp in the
# offline twin and the diagnosis, where the real-wire twin's chamber starts and relaxes
# to when stopped, where the dry run starts a campaign, and the default safe setpoint
# (the engine's ``safe_c``, a chamber map's ``[safe] setpoint_c``).
AMBIENT_C = 23.0
DEFAULT_RAMP_C_PER_MIN = 2.0  # working-setpoint ramp between steps (seed Table 3: 0.1–5 °C/min)
DEFAULT_AIR_TAU_S = 120.0  # the air's settling behind the working setpoint


def lag_step(y: float, u: float, dt_s: float, tau_s: float) -> float:
    """One exact step of ``y' = (u − y)/τ``, ``u`` held over ``dt_s``: ``u + (y − u)·e^{−dt/τ}``.

    The twins' time step (floats; ``tau_s ≤ 0`` returns ``u``, no lag). For a whole
    series on a grid use :func:`lag_series`. ``np.exp``, not ``math.exp``: they differ
    in the last bit on ~5 % of arguments, and the offline twin, behind every benchmark
    figure, has always stepped with ``np.exp``.
    """
    if tau_s <= 0:
        return u
    return u + (y - u) * np.exp(-dt_s / tau_s)


def rate_limited(current_c: float, target_c: float, max_step_c: float) -> float:
    """``current_c`` moved towards ``target_c`` by at most ``max_step_c`` (≥ 0; ``inf`` = no limit).

    A ramp-rate limit (°C/min × the step) or a chamber's own heating/cooling capability:
    within one step of the target it lands exactly on the target.
    """
    diff = target_c - current_c
    if abs(diff) <= max_step_c:
        return target_c
    return current_c + math.copysign(max_step_c, diff)


def lag_series(u: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    """:func:`lag_step` applied along a series ``u`` sampled every ``dt_s``, ``y[0] = u[0]``.

    ``y[i] = u[i] + (y[i−1] − u[i])·a`` with ``a = e^{−dt/τ}``, i.e. each step holds the
    input at its end value; written as the equivalent linear filter
    ``y[i] = (1 − a)·u[i] + a·y[i−1]`` so a campaign-long grid costs one C loop.
    """
    u = np.asarray(u, dtype=float)
    if tau_s <= 0:
        return u.copy()
    from scipy.signal import lfilter  # on first use: the service imports AMBIENT_C lightly

    a = float(np.exp(-dt_s / tau_s))
    y, _ = lfilter([1.0 - a], [1.0, -a], u, zi=[a * u[0]])
    return y


def ramp_breakpoints(
    t_s: np.ndarray,
    steps: np.ndarray,
    step_temp_c: dict[int, float],
    ramp_c_per_min: float,
    ambient_c: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints (times s, temperatures °C) of the piecewise-linear temperature history
    that a recording's plateaus imply; linear between them, constant after the last.

    Each plateau (step id → its temperature) holds from where it is reached to its
    last reading; between plateaus the temperature ramps at ``ramp_c_per_min``, starting
    at the previous plateau's last reading (the recording does not hold the ramps).
    Before the first plateau the campaign starts at ``ambient_c``, ramps, then soaks as
    long as the median of the other plateaus' soaks.
    """
    ids = sorted(step_temp_c)
    first = {s: float(t_s[steps == s].min()) for s in ids}
    last = {s: float(t_s[steps == s].max()) for s in ids}
    rate = ramp_c_per_min / 60.0
    temp = [step_temp_c[s] for s in ids]
    soaks = [
        first[ids[k]] - last[ids[k - 1]] - abs(temp[k] - temp[k - 1]) / rate
        for k in range(1, len(ids))
    ]
    soak = max(float(np.median(soaks)), 0.0) if soaks else 0.0
    t0 = first[ids[0]] - soak - abs(temp[0] - ambient_c) / rate
    bt, bv = [t0, t0 + abs(temp[0] - ambient_c) / rate], [ambient_c, temp[0]]
    for k in range(1, len(ids)):
        start = max(last[ids[k - 1]], bt[-1])
        bt += [start, start + abs(temp[k] - temp[k - 1]) / rate]
        bv += [temp[k - 1], temp[k]]
    return np.asarray(bt), np.asarray(bv)


def lag_behind_piecewise_linear(
    bt_s: np.ndarray, bv_c: np.ndarray, t_s: np.ndarray, tau_s: float
) -> np.ndarray:
    """``δ = y − u`` at times ``t_s`` for ``y`` lagging ``u`` (τ) with ``u`` piecewise linear.

    ``u`` passes through the breakpoints (``bt_s``, ``bv_c``) and is constant after the
    last; ``y`` starts on ``u`` at ``bt_s[0]``. On a segment of slope ``r``,
    ``δ' = −δ/τ − r`` is solved exactly: ``δ(t) = −rτ + (δ(t_i) + rτ)·e^{−(t − t_i)/τ}``,
    so the end of a plateau is not smeared into the next ramp.
    """
    if tau_s <= 0:
        return np.zeros(np.shape(t_s))
    dt_seg = np.diff(bt_s)
    slope = np.divide(np.diff(bv_c), dt_seg, out=np.zeros_like(dt_seg), where=dt_seg > 0)
    slope = np.append(slope, 0.0)  # constant after the last breakpoint
    delta = np.zeros(bt_s.size)  # δ at each breakpoint; y starts on u
    for i in range(1, bt_s.size):
        r = slope[i - 1]
        delta[i] = -r * tau_s + (delta[i - 1] + r * tau_s) * np.exp(-dt_seg[i - 1] / tau_s)
    i = np.clip(np.searchsorted(bt_s, t_s, side="right") - 1, 0, bt_s.size - 1)
    r = slope[i]
    return -r * tau_s + (delta[i] + r * tau_s) * np.exp(-(t_s - bt_s[i]) / tau_s)
