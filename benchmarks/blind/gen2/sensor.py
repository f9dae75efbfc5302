"""The second generator's sensor: a full 3×3 gain matrix and a bias, each in Chebyshev terms.

Written apart from ``simulators/truth.py`` on purpose (another parametrisation, so the
benchmark does not share the diagnosis' assumptions):

    raw = (G0 + G1·u + G2·T2(u))·f + Σ_k c_k·T_k(u),   u = (T − 22.5 °C)/62.5 °C

with T_k the Chebyshev polynomials (T2 = 2u² − 1, T3 = 4u³ − 3u) on the −40…85 °C range,
G0 = I + scale errors on the diagonal and arbitrary (non-antisymmetric) off-diagonal
coupling, G1, G2 its thermal change. No rotation angles, no triangular non-orthogonality.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

T_MID_C, T_HALF_C = 22.5, 62.5


def cheb(u: np.ndarray, k: int) -> np.ndarray:
    return np.cos(k * np.arccos(np.clip(u, -1.0, 1.0)))


def u_of(temp_c: np.ndarray) -> np.ndarray:
    return (np.asarray(temp_c, float) - T_MID_C) / T_HALF_C


@dataclass
class Sensor2:
    g0: np.ndarray  # (3,3) gain at 22.5 °C
    g1: np.ndarray  # (3,3) per u
    g2: np.ndarray  # (3,3) × T2(u)
    bias_cheb_g: np.ndarray  # (4,3) bias Chebyshev coefficients, g

    def gain(self, temp_c: np.ndarray) -> np.ndarray:
        u = u_of(temp_c)
        return (self.g0[None] + u[:, None, None] * self.g1[None]
                + cheb(u, 2)[:, None, None] * self.g2[None])

    def bias_g(self, temp_c: np.ndarray) -> np.ndarray:
        u = u_of(temp_c)
        return sum(cheb(u, k)[:, None] * self.bias_cheb_g[k][None] for k in range(4))

    def output_g(self, force_g: np.ndarray, temp_c: np.ndarray) -> np.ndarray:
        """Raw output (N,3) for specific force (N,3) at die temperature (N,)."""
        return np.einsum("nij,nj->ni", self.gain(temp_c), force_g) + self.bias_g(temp_c)

    def rotated_z(self, angle_rad: float) -> Sensor2:
        """The same sensor re-mounted by ``angle_rad`` about its own z axis."""
        c, s = np.cos(angle_rad), np.sin(angle_rad)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return Sensor2(self.g0 @ rz, self.g1 @ rz, self.g2 @ rz, self.bias_cheb_g.copy())


def draw_sensor(rng: np.random.Generator) -> Sensor2:
    """An ADXL355-class sensor: scale ±1.5 %, coupling ±6 mrad, bias ±40 mg, tempcos
    up to 0.1 mg/°C and 150 ppm/°C over the half range, curvature a quarter of that."""
    g0 = np.eye(3) + np.diag(rng.uniform(-0.015, 0.015, 3))
    off = ~np.eye(3, dtype=bool)
    g0[off] = rng.uniform(-6e-3, 6e-3, 6)
    g1 = np.diag(rng.uniform(-150e-6, 150e-6, 3) * T_HALF_C)
    g1[off] = rng.uniform(-5e-6, 5e-6, 6) * T_HALF_C
    g2 = rng.uniform(-0.25, 0.25, (3, 3)) * np.abs(g1).max()
    bias = np.zeros((4, 3))
    bias[0] = rng.uniform(-40e-3, 40e-3, 3)
    bias[1] = rng.uniform(-0.1e-3, 0.1e-3, 3) * T_HALF_C
    bias[2] = rng.uniform(-0.25, 0.25, 3) * np.abs(bias[1]).max()
    bias[3] = rng.uniform(-0.08, 0.08, 3) * np.abs(bias[1]).max()
    return Sensor2(g0, g1, g2, bias)
