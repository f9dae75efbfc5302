"""Effects of the second generator, each written from its physical description only.

Catalogue effects (docs/effects.md ids) and two outside it. Every function returns a
change of one piece of the scene; ``simulate.py`` applies it. Magnitude ``m`` in the unit of
``UNIT`` times a drawn pattern (signs and relative sizes per axis) fixed by the case's seed.
"""

from __future__ import annotations

import numpy as np

UNIT = {
    "thermal_lag": "s", "thermal_hysteresis": "ug", "temperature_rate": "ug_per_c_per_min",
    "scale_nonlinearity": "ug_per_g2", "cross_coupling": "ug_per_g2", "bias_drift": "ug_per_h",
    "session_offset": "ug", "outlier": "ug", "vibration_rectification": "per_g",
    "temperature_sensor": "c", "turntable_tilt": "urad", "turntable_encoder": "urad",
    "adc_band": "ug", "crack": "ug",
}
# Which catalogue id a case's effect should be named by (tilt and encoder: one id).
CATALOGUE_ID = {k: k for k in UNIT} | {"turntable_tilt": "turntable_geometry",
                                       "turntable_encoder": "turntable_geometry"}
OUTSIDE = ("adc_band", "crack")
DOF = {"thermal_lag": 1, "thermal_hysteresis": 3, "temperature_rate": 3,
       "scale_nonlinearity": 6, "cross_coupling": 3, "bias_drift": 3, "session_offset": 3,
       "outlier": 3, "vibration_rectification": 3, "temperature_sensor": 1,
       "turntable_tilt": 2, "turntable_encoder": 2}


def pattern(rng: np.random.Generator, n_steps: int, n_readings: int) -> dict:
    """Per-axis shape (unit max), the step a change starts at, rows hit, a band of codes."""
    w = rng.uniform(0.3, 1.0, 3) * rng.choice([-1.0, 1.0], 3)
    w /= np.abs(w).max()
    return {"axes": w.tolist(), "from_step": int(rng.integers(1, max(n_steps - 1, 2))),
            "rows": sorted(rng.choice(n_readings, 2, replace=False).tolist()),
            "axis": int(rng.integers(0, 3)), "band_lo_g": float(rng.uniform(0.2, 0.6)),
            "tilt_dir": float(rng.uniform(0, 2 * np.pi)), "crack_frac": float(rng.uniform(.3, .7))}


def lab_up(eid: str, m: float, pat: dict) -> np.ndarray:
    """Lab 'up' seen by the table: tilted by m µrad in direction tilt_dir for a tilted axis."""
    if eid != "turntable_tilt":
        return np.array([0.0, 0.0, 1.0])
    a, d = m * 1e-6, pat["tilt_dir"]
    up = np.array([a * np.cos(d), a * np.sin(d), 1.0])
    return up / np.linalg.norm(up)


def encoder_error_rad(eid: str, m: float, beta_rad: np.ndarray) -> np.ndarray:
    """Outer-axis encoder error: eccentricity (once per turn) plus a twice-per-turn term."""
    if eid != "turntable_encoder":
        return np.zeros_like(beta_rad)
    return m * 1e-6 * (np.sin(beta_rad) + 0.5 * np.sin(2 * beta_rad + 0.7))


def output_offset_g(eid: str, m: float, pat: dict, s: dict) -> np.ndarray:
    """Extra output (N,3) g for effects that add to the output at the reading's state ``s``
    (force_g, direction, t_h, session, die_rate_c_per_min, vib_sd_g, step, t_s)."""
    w = np.asarray(pat["axes"])
    f = s["force_g"]
    n = len(f)
    out = np.zeros((n, 3))
    if eid == "thermal_hysteresis":
        out = s["direction"][:, None] * w * m * 1e-6
    elif eid == "bias_drift":
        out = s["t_h"][:, None] * w * m * 1e-6
    elif eid == "session_offset":
        out = s["session"][:, None] * w * m * 1e-6
    elif eid == "temperature_rate":
        out = s["die_rate_c_per_min"][:, None] * w * m * 1e-6
    elif eid == "scale_nonlinearity":
        out = (f**2 * w + 0.5 * f**3 * w[::-1]) * m * 1e-6
    elif eid == "cross_coupling":
        k = w * m * 1e-6  # k_xy, k_xz, k_yz
        out[:, 0] = k[0] * f[:, 0] * f[:, 1] + k[1] * f[:, 0] * f[:, 2]
        out[:, 1] = k[0] * f[:, 0] * f[:, 1] + k[2] * f[:, 1] * f[:, 2]
        out[:, 2] = k[1] * f[:, 0] * f[:, 2] + k[2] * f[:, 1] * f[:, 2]
    elif eid == "outlier":
        out[pat["rows"]] = w * m * 1e-6
    elif eid == "vibration_rectification":
        out = s["vib_sd_g"][:, None] ** 2 * w * m
    elif eid == "crack":
        after = s["t_s"] >= s["crack_t_s"]
        out[after, pat["axis"]] = m * 1e-6 * (1.0 + 0.5 * f[after, pat["axis"]])
    return out


def temperature_channel_shift_c(eid: str, m: float, pat: dict, steps: np.ndarray) -> np.ndarray:
    """The temperature channel steps by m °C from ``from_step`` on (a re-zeroed channel)."""
    if eid != "temperature_sensor":
        return np.zeros(len(steps))
    return np.where(steps >= pat["from_step"], m, 0.0)


def adc_band_error_g(eid: str, m: float, pat: dict, samples_g: np.ndarray,
                     axis: int) -> np.ndarray:
    """ADC error confined to a band of codes: +m µg while one axis's code lies in
    [band_lo, band_lo + 0.15 g) (a defective range of the converter), sample by sample."""
    if eid != "adc_band" or axis != pat["axis"]:
        return np.zeros_like(samples_g)
    lo = pat["band_lo_g"]
    inside = (np.abs(samples_g) >= lo) & (np.abs(samples_g) < lo + 0.15)
    return np.where(inside, m * 1e-6, 0.0)
