"""Accuracy metrics of the seed paper: Eq. 9 RMSE, Eq. 10 tilt + SEOQ (Table 5), thermal drift.

* :func:`rmse_norm_ug` -- Eq. 9, RMS of (|a| − g) in µg.
* :func:`vector_error_ug` -- where references exist: per-axis RMS of (a − ref) in µg.
* :func:`tilt_angles_deg` -- Eq. 10: pitch φ = atan(−Y/√(X²+Z²)), roll θ = atan(X/−Z).
* :func:`seoq_percent` -- Table 5's "Sensor Error Optimization Quantity": the
  change of the angle between before and after calibration relative to the
  30° maximum angle, |φ_before − φ_after| / 30° · 100 %. (The seed's wording is
  vague; this definition reproduces every entry of Table 5, e.g. 0;0 →
  |−0.77 − (−0.70)|/30 = 0.2 %, |0.59 − (−0.30)|/30 = 3.0 %.)
* :func:`thermal_drift` -- drift over the temperature range (mg) and its
  slope (µg/K) per axis, as the seed's "1346 µg/K → 37 µg/K" (Fig. 11) and
  "−13.2 mg → −0.9 mg" (abstract).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.fit import rmse_norm_ug

__all__ = [
    "ThermalDrift",
    "rmse_norm_ug",
    "seoq_percent",
    "thermal_drift",
    "tilt_angles_deg",
    "tilt_table",
    "vector_error_ug",
    "drift_before_after",
]

SEOQ_MAX_ANGLE_DEG = 30.0


def vector_error_ug(cal_g: np.ndarray, ref_g: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-axis RMS of (calibrated − reference) in µg (3,), and the RMS over all axes."""
    err = np.asarray(cal_g, float) - np.asarray(ref_g, float)
    per_axis = np.sqrt(np.mean(err**2, axis=0)) * 1e6
    return per_axis, float(np.sqrt(np.mean(err**2)) * 1e6)


def tilt_angles_deg(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 10: pitch φ = atan(−Y/√(X²+Z²)), roll θ = atan(X/−Z), degrees."""
    a = np.atleast_2d(np.asarray(g, float))
    x, y, z = a[:, 0], a[:, 1], a[:, 2]
    pitch = np.degrees(np.arctan(-y / np.sqrt(x * x + z * z)))
    with np.errstate(divide="ignore"):
        roll = np.degrees(np.arctan(x / -z))
    return pitch, roll


def seoq_percent(
    before_deg: np.ndarray, after_deg: np.ndarray, max_angle_deg: float = SEOQ_MAX_ANGLE_DEG
) -> np.ndarray:
    """Table 5 SEOQ: |angle before − angle after| / max angle · 100 %."""
    return (
        np.abs(np.asarray(before_deg, float) - np.asarray(after_deg, float)) / max_angle_deg * 100.0
    )


def tilt_table(raw_g: np.ndarray, cal_g: np.ndarray, ref_g: np.ndarray) -> list[dict[str, float]]:
    """Rows of the seed's Table 5: reference, uncalibrated and calibrated (φ; θ), SEOQ."""
    rp, rr = tilt_angles_deg(ref_g)
    bp, br = tilt_angles_deg(raw_g)
    ap, ar = tilt_angles_deg(cal_g)
    sp, sr = seoq_percent(bp, ap), seoq_percent(br, ar)
    return [
        {
            "ref_pitch_deg": float(rp[i]),
            "ref_roll_deg": float(rr[i]),
            "raw_pitch_deg": float(bp[i]),
            "raw_roll_deg": float(br[i]),
            "cal_pitch_deg": float(ap[i]),
            "cal_roll_deg": float(ar[i]),
            "seoq_pitch_pct": float(sp[i]),
            "seoq_roll_pct": float(sr[i]),
            "err_raw_deg": float(np.hypot(bp[i] - rp[i], br[i] - rr[i])),
            "err_cal_deg": float(np.hypot(ap[i] - rp[i], ar[i] - rr[i])),
        }
        for i in range(rp.size)
    ]


@dataclass(frozen=True)
class ThermalDrift:
    """Linear temperature dependence of an output, per axis (x, y, z) and of |g|."""

    slope_ug_per_k: np.ndarray  # (3,) least-squares slope
    drift_mg: np.ndarray  # (3,) slope × (T_max − T_min): signed change over the range
    norm_slope_ug_per_k: float  # slope of |g|
    range_c: tuple[float, float]

    def as_dict(self) -> dict[str, object]:
        return {
            "slope_ug_per_k": [round(float(v), 2) for v in self.slope_ug_per_k],
            "drift_mg": [round(float(v), 4) for v in self.drift_mg],
            "norm_slope_ug_per_k": round(float(self.norm_slope_ug_per_k), 2),
            "abs_slope_ug_per_k": round(float(np.linalg.norm(self.slope_ug_per_k)), 2),
            "range_c": [round(v, 3) for v in self.range_c],
        }


def thermal_drift(
    values_g: np.ndarray,
    temperature_c: np.ndarray,
    groups: np.ndarray | None = None,
    g_local: float = 1.0,
) -> ThermalDrift:
    """Slope (µg/K) and drift over the range (mg) of each axis against temperature.

    ``groups`` (e.g. the position index of a campaign) removes each group's own
    mean first, so readings in different orientations can be pooled: what is
    left is the change with temperature at a fixed orientation. With one
    orientation (the seed's cooling run, Fig. 11) leave ``groups`` None.
    """
    v = np.asarray(values_g, float)
    T = np.asarray(temperature_c, float)
    norm = np.linalg.norm(v, axis=1) - g_local
    y = np.column_stack([v, norm])
    if groups is None:
        groups = np.zeros(T.size, int)
    # Group means by one pass over the rows (bincount), not one mask per group: a
    # recording with a position index per reading has as many groups as rows / steps,
    # and the masks made this O(rows²) (issue 10: 100 k rows spent 21 s here).
    y, Tc = minus_group_means(groups, y), minus_group_means(groups, T)
    denom = float(np.sum(Tc * Tc))
    slope = (Tc @ y) / denom if denom > 0 else np.full(4, np.nan)  # g/K
    span = float(np.max(T) - np.min(T))
    return ThermalDrift(
        slope_ug_per_k=slope[:3] * 1e6,
        drift_mg=slope[:3] * span * 1e3,
        norm_slope_ug_per_k=float(slope[3] * 1e6),
        range_c=(float(np.min(T)), float(np.max(T))),
    )


def minus_group_means(groups: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` (N,) or (N, k) with each group's own mean removed (one bincount pass)."""
    _, inverse = np.unique(np.asarray(groups), return_inverse=True)
    inverse = inverse.ravel()
    count = np.bincount(inverse).astype(float)
    v = np.asarray(values, float)
    cols = v.reshape(v.shape[0], -1)
    means = np.column_stack(
        [np.bincount(inverse, weights=cols[:, j]) / count for j in range(cols.shape[1])]
    )
    return (cols - means[inverse]).reshape(v.shape)


def drift_before_after(
    raw_g: np.ndarray,
    cal_g: np.ndarray,
    temperature_c: np.ndarray,
    groups: np.ndarray | None = None,
    g_local: float = 1.0,
) -> dict[str, dict[str, object]]:
    """:func:`thermal_drift` of the raw and the compensated output, as a JSON-able dict."""
    return {
        "before": thermal_drift(raw_g, temperature_c, groups, g_local).as_dict(),
        "after": thermal_drift(cal_g, temperature_c, groups, g_local).as_dict(),
    }
