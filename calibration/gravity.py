"""Local gravity for ``calibrate``: given in g, or WGS84 normal gravity at a place.

A static tumble measures every position against the same |g|: a different
local gravity scales all three scale factors by the same ratio and leaves the
residuals unchanged, so local gravity cannot be identified from the tumble
itself (the seed calibrates against 1 g). It is an input: ``--gravity-g G``, or
``--latitude-deg L --height-m H`` for the normal gravity of the WGS84
ellipsoid (Somigliana's closed formula) with the WGS84 free-air correction
(NIMA TR8350.2, Eq. 4-1 and 4-3), expressed in units of standard gravity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

STANDARD_GRAVITY_M_S2 = 9.80665  # 1 g by definition (CGPM 1901)

# WGS84 defining and derived constants (NIMA TR8350.2, 3rd ed., tables 3.1-3.3)
WGS84_A_M = 6378137.0  # semi-major axis
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_GAMMA_E_M_S2 = 9.7803253359  # normal gravity at the equator
WGS84_K = 0.00193185265241  # Somigliana's constant (b·γp)/(a·γe) − 1
WGS84_E2 = 0.00669437999013  # first eccentricity squared
WGS84_M = 0.00344978650684  # ω²a²b/GM

# Plausible bounds: Earth's surface gravity spans 0.9973..1.0026 g; a value like
# 9.81 is almost certainly m/s² given where g was expected.
GRAVITY_G_RANGE = (0.95, 1.05)
HEIGHT_M_RANGE = (-1000.0, 20000.0)  # below the Dead Sea shore .. stratosphere balloons


class GravityError(ValueError):
    """A local-gravity input out of its plausible range (message names the flag)."""


@dataclass(frozen=True)
class LocalGravity:
    g: float  # in units of standard gravity
    source: str  # how it was obtained, for reports and the model file

    @property
    def m_per_s2(self) -> float:
        return self.g * STANDARD_GRAVITY_M_S2

    def to_dict(self) -> dict[str, object]:
        return {"g_local": self.g, "m_per_s2": round(self.m_per_s2, 7), "source": self.source}


def normal_gravity_m_s2(latitude_deg: float, height_m: float = 0.0) -> float:
    """WGS84 normal gravity (m/s²) at geodetic latitude and ellipsoidal height.

    Somigliana: γ = γe (1 + k sin²φ) / √(1 − e² sin²φ); free-air (second order):
    γh = γ [1 − 2/a (1 + f + m − 2 f sin²φ) h + 3 h²/a²].
    """
    s2 = math.sin(math.radians(latitude_deg)) ** 2
    gamma = WGS84_GAMMA_E_M_S2 * (1.0 + WGS84_K * s2) / math.sqrt(1.0 - WGS84_E2 * s2)
    a = WGS84_A_M
    return gamma * (1.0 - 2.0 / a * (1.0 + WGS84_F + WGS84_M - 2.0 * WGS84_F * s2) * height_m
                    + 3.0 * height_m**2 / a**2)


def from_arguments(
    gravity_g: float | None, latitude_deg: float | None, height_m: float | None
) -> LocalGravity | None:
    """The local gravity the flags ask for, None when none was given."""
    if gravity_g is not None and (latitude_deg is not None or height_m is not None):
        raise GravityError("--gravity-g and --latitude-deg/--height-m are alternatives; give one")
    if gravity_g is not None:
        lo, hi = GRAVITY_G_RANGE
        if not (math.isfinite(gravity_g) and lo <= gravity_g <= hi):
            raise GravityError(
                f"--gravity-g: {gravity_g:g} is not a local gravity in units of standard gravity "
                f"(9.80665 m/s²; expected {lo}..{hi}; for m/s² divide by 9.80665)")
        return LocalGravity(float(gravity_g), f"--gravity-g {gravity_g:g}")
    if height_m is not None and latitude_deg is None:
        raise GravityError("--height-m needs --latitude-deg")
    if latitude_deg is None:
        return None
    if not (math.isfinite(latitude_deg) and -90.0 <= latitude_deg <= 90.0):
        raise GravityError(f"--latitude-deg: {latitude_deg:g} is not a latitude (-90..90 deg)")
    h = 0.0 if height_m is None else float(height_m)
    if not (math.isfinite(h) and HEIGHT_M_RANGE[0] <= h <= HEIGHT_M_RANGE[1]):
        raise GravityError(
            f"--height-m: {h:g} m is outside {HEIGHT_M_RANGE[0]:g}..{HEIGHT_M_RANGE[1]:g} m")
    g_ms2 = normal_gravity_m_s2(float(latitude_deg), h)
    return LocalGravity(
        g_ms2 / STANDARD_GRAVITY_M_S2,
        f"WGS84 normal gravity at latitude {latitude_deg:g} deg, height {h:g} m "
        f"(Somigliana + free-air): {g_ms2:.6f} m/s²")


NOT_IDENTIFIABLE_NOTE = (
    "local gravity cannot be identified in a static tumble (a different |g| scales "
    "sx, sy, sz by the same ratio with unchanged residuals): it is an input"
)
