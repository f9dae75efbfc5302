"""Position schedules: the gravity directions (sensor frame, unit vectors) a campaign visits.

* :func:`table1` -- the seed's Table 1: three great circles of 8 positions at
  45° steps (rotation about z with y vertical first, about y with z vertical
  first, about x with z vertical first): 24 positions.
* :func:`tilt_fixture` -- six faces plus a hand-placed wedge ring (manual rigs).
* :func:`sphere` -- n points spread uniformly over the sphere (Fibonacci
  lattice); ``sphere(1296)`` is the seed's §4.2 reference set.
* :data:`TABLE4_NOP` -- the numbers of positions of the seed's Table 4 (Fig. 8).
* :func:`identifiability` -- which SFEM parameters a schedule determines in a mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration import sfem

TABLE4_NOP: tuple[int, ...] = (1296, 648, 324, 162, 81, 64, 48, 36, 24, 21, 18, 16, 12)


def table1() -> np.ndarray:
    """Seed Table 1 (24 positions) as unit gravity vectors in the sensor frame, (24,3)."""
    th = np.deg2rad(np.arange(8) * 45.0)
    s, c, z = np.sin(th), np.cos(th), np.zeros(8)
    about_z = np.column_stack([s, c, z])  # Py1 vertical, rotate Px/Py (Pz fixed)
    about_y = np.column_stack([s, z, c])  # Pz2 vertical, rotate Px/Pz (Py fixed)
    about_x = np.column_stack([z, s, c])  # Pz3 vertical, rotate Py/Pz (Px fixed)
    return _clean(np.vstack([about_z, about_y, about_x]))


def six_position() -> np.ndarray:
    """Ferraris / Khan-Ranj ±x, ±y, ±z (exactly determined for 12 parameters)."""
    return np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
    )


def cube14() -> np.ndarray:
    """Six faces plus eight cube diagonals: oblique positions that expose a³ and cross terms."""
    diag = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    return np.vstack([six_position(), diag / np.sqrt(3.0)])


def tilt_fixture(tilt_deg: float = 45.0, n_azimuth: int = 8) -> np.ndarray:
    """Six faces plus a hand-placed wedge: 6 + 2·``n_azimuth`` positions.

    For labs without a turntable (docs/manual-fixtures.md): the sensor first lies
    on each face of its cube, then sits on a wedge of ``tilt_deg`` with +z away
    from the wedge and is turned in its plane by 360°/``n_azimuth`` steps, then
    the same with -z away. On the wedge the specific force in the sensor frame is
    (sin θ cos ψ, sin θ sin ψ, ±cos θ) (seed paper eq. (1), |f| = 1 g). The six
    faces alone leave the cross-axis terms undetermined in norm mode; with the
    ring of 8 at 45° all nine |g|-visible parameters are determined (tested).
    """
    if not 0.0 < tilt_deg < 90.0 or n_azimuth < 3:
        raise ValueError(f"tilt fixture needs 0 < tilt_deg < 90 and n_azimuth >= 3, "
                         f"got {tilt_deg}, {n_azimuth}")
    th = np.deg2rad(tilt_deg)
    psi = np.deg2rad(np.arange(n_azimuth) * 360.0 / n_azimuth)
    ring = np.column_stack([np.sin(th) * np.cos(psi), np.sin(th) * np.sin(psi),
                            np.full(n_azimuth, np.cos(th))])
    return _clean(np.vstack([six_position(), ring, ring * np.array([1.0, 1.0, -1.0])]))


def sphere(n: int) -> np.ndarray:
    """n unit vectors spread uniformly over the sphere (Fibonacci lattice)."""
    if n < 1:
        raise ValueError(f"sphere needs n >= 1 positions, got {n}")
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return _clean(np.column_stack([r * np.cos(phi), r * np.sin(phi), z]))


def get_schedule(name: str) -> np.ndarray:
    """Schedule by name: table1, six, cube14, tilt / tilt<DEG> (hand wedge, default 45°),
    sphere<N> (e.g. sphere1296), table1+cube14."""
    key = name.strip().lower()
    if "+" in key:
        return np.vstack([get_schedule(k) for k in key.split("+")])
    if key == "table1":
        return table1()
    if key in ("six", "six_position", "ferraris"):
        return six_position()
    if key == "cube14":
        return cube14()
    if key == "tilt":
        return tilt_fixture()
    if key.startswith("tilt") and key[4:].isdigit() and 0 < int(key[4:]) < 90:
        return tilt_fixture(float(key[4:]))
    if key.startswith("sphere") and key[6:].isdigit():
        return sphere(int(key[6:]))
    raise ValueError(
        f"unknown position schedule {name!r}; expected table1, six, cube14, tilt, tilt<DEG> "
        "or sphere<N>"
    )


@dataclass(frozen=True)
class Identifiability:
    mode: str
    rank: int
    n_params: int
    condition: float
    undetermined: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return not self.undetermined


def identifiability(
    ref_g: np.ndarray,
    mode: str = "reference",
    *,
    rel_tol: float = 1e-9,
    component_tol: float = 1e-6,
) -> Identifiability:
    """Which SFEM parameters the schedule determines (Jacobian rank at nominal parameters).

    Singular values below ``rel_tol`` × the largest count as zero (the default
    asks for exact rank deficiency; a fit on measured directions passes ~1e-3 so
    that an almost-degenerate schedule, e.g. six axis directions a little off
    true, counts as degenerate). A parameter is undetermined when its unit
    vector has a projection longer than ``component_tol`` on that null space.
    """
    ref = np.asarray(ref_g, dtype=float)
    p = sfem.identity_vector()
    _, jac = sfem.forward_jacobian(p, ref)  # raw ≈ ref at nominal parameters
    names = sfem.PARAM_NAMES
    if mode == "reference":
        J = jac.reshape(-1, sfem.N_PARAMS)
        free = np.ones(sfem.N_PARAMS, bool)
    elif mode == "norm":
        J = sfem.norm_jacobian(ref, jac)  # raw ≈ ref: f's direction is the reference's
        free = np.array([True] * 9 + [False] * 3)
        J = J[:, free]
    else:
        raise ValueError(f"mode must be 'reference' or 'norm', got {mode!r}")
    # Only V is needed; a full U of a 1296-position schedule would be 3888².
    _, sv, vt = np.linalg.svd(J, full_matrices=J.shape[0] < J.shape[1])
    tol = rel_tol * (sv[0] if sv.size else 1.0)
    rank = int(np.sum(sv > tol))
    null = vt[rank:]
    free_names = [n for n, f in zip(names, free, strict=True) if f]
    undetermined = [
        n for k, n in enumerate(free_names)
        if null.size and np.linalg.norm(null[:, k]) > component_tol
    ]
    if mode == "norm":
        undetermined += ["mx", "my", "mz"]
    cond = float(sv[0] / sv[rank - 1]) if rank else float("inf")
    return Identifiability(mode, rank, int(free.sum()), cond, tuple(undetermined))


def _clean(v: np.ndarray) -> np.ndarray:
    v = np.where(np.abs(v) < 1e-12, 0.0, v)
    return v / np.linalg.norm(v, axis=1, keepdims=True)
