"""The gen3 sensor: output = K(T)·g + b(T), K a full 3×3 gain matrix quadratic in ΔT and b
cubic in ΔT (issue 22: a parametrisation other than the SFEM's chain M·C·S, within what the
12-parameter model with smooth thermal dependence represents). ADXL355-class magnitudes:
bias ≤ 25 mg, thermal bias slope ≤ 0.1 mg/°C, scale TC ≤ 100 ppm/°C, cross-axis ≤ 1 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

T_REF_C = 20.0  # the temperature the polynomials are expanded about


@dataclass(frozen=True)
class GainBiasSensor:
    """K(T) = K0 + K1·ΔT + K2·ΔT² (per g, per °C, per °C²), b(T) = Σ b_k·ΔT^k (g)."""

    k0: np.ndarray  # (3, 3)
    k1_per_c: np.ndarray  # (3, 3)
    k2_per_c2: np.ndarray  # (3, 3)
    bias_g: np.ndarray  # (4, 3): rows ΔT^0 … ΔT^3

    def gain(self, t_c: float) -> np.ndarray:
        dt = t_c - T_REF_C
        return self.k0 + self.k1_per_c * dt + self.k2_per_c2 * dt**2

    def bias(self, t_c: float) -> np.ndarray:
        dt = t_c - T_REF_C
        return self.bias_g.T @ np.array([1.0, dt, dt**2, dt**3])

    def output_g(self, force_g: np.ndarray, t_c: float) -> np.ndarray:
        """The noiseless output (g) for the specific force ``force_g`` in the sensor frame."""
        return self.gain(t_c) @ force_g + self.bias(t_c)

    def slope_g_per_c(self) -> float:
        """A bound on |∂output/∂T| at 1 g over −40…60 °C (for the settling time)."""
        worst = 0.0
        for t in np.linspace(-40.0, 60.0, 21):
            dk = self.k1_per_c + 2.0 * self.k2_per_c2 * (t - T_REF_C)
            dt = t - T_REF_C
            db = self.bias_g[1] + 2 * self.bias_g[2] * dt + 3 * self.bias_g[3] * dt**2
            worst = max(worst, float(np.max(np.abs(dk).sum(axis=1) + np.abs(db))))
        return worst


def draw_sensor(rng: np.random.Generator) -> GainBiasSensor:
    """One ADXL355-class sensor: scale ±1 %, off-diagonal (misalignment and cross-axis)
    ±0.8 %, scale TC ±100 ppm/°C, bias ±25 mg with slope ±0.1 mg/°C and a bend ≤ ~0.5 mg
    over the range; the quadratic gain term keeps K2·ΔT² within ~7e-4 at the ends."""
    k0 = np.eye(3) + np.diag(rng.uniform(-0.01, 0.01, 3))
    off = ~np.eye(3, dtype=bool)
    k0[off] += rng.uniform(-0.008, 0.008, 6)
    k1 = np.diag(rng.uniform(-100e-6, 100e-6, 3))
    k1[off] += rng.uniform(-5e-6, 5e-6, 6)
    k2 = np.diag(rng.uniform(-0.2e-6, 0.2e-6, 3))
    bias = np.vstack([
        rng.uniform(-25e-3, 25e-3, 3),
        rng.uniform(-0.1e-3, 0.1e-3, 3),
        rng.uniform(-1.4e-7, 1.4e-7, 3),
        rng.uniform(-1.4e-9, 1.4e-9, 3),
    ])
    return GainBiasSensor(k0=k0, k1_per_c=k1, k2_per_c2=k2, bias_g=bias)
