"""Sweep circles of a table schedule, found from the references alone, and the two shapes a
table's geometry takes on them (``turntable_geometry``, issue 22).

Why: a recording holds the specific force's direction in the sensor frame, not the table
angles. But a table turns the sensor about one axis at a time, and a sweep about a
horizontal axis moves the reference along a *great circle* whose normal is that axis in the
sensor frame (constant during the sweep: the axis carries the inner assembly, the sensor
included). Great circles holding at least ``MIN_CIRCLE_DIRECTIONS`` distinct references are
therefore the sweeps, and each one gives the rotation axis ``n`` and the commanded angle φ
along it (up to its origin and sense), without any angle the recording lacks.

On a circle with axis ``n`` and references ``f`` (|f| = g, rotation δθ moves f by δθ × f):

* a **tilted table axis** (lab up tilted by t = (t∥, t⊥) against the horizontal axis) turns
  gravity in the base frame; seen in the sensor frame it is ``t∥·n + t⊥·(f × n)``, the same
  two numbers at every pose of the sweep (the component along the axis, and a constant
  offset of the commanded angle). Two columns per circle.
* an **encoder error** ε(φ) of the sweeping axis turns f about ``n`` by ε: ``ε(φ)·(n × f)``,
  periodic in the commanded angle; its first two harmonics (cos φ, sin φ, cos 2φ, sin 2φ)
  are four columns per circle (their span does not depend on the origin or sense of φ,
  which the references do not fix; its constant is the tilt's t⊥).

Per circle, not tied across circles: the sense of each axis (±n) is not in the references,
and a single-axis table remounted between sweeps shares nothing but the base. Poses on
several circles (the poles every sweep of a two-axis table passes through) are left out:
which sweep reached them is not in the references.
"""

from __future__ import annotations

import numpy as np

# A reference lies on a circle when |n·u| is below this (rad): commanded references are
# exact; a random sphere schedule then has no accidental circle of 5 (see the tests).
CIRCLE_TOL = 2e-3
MIN_CIRCLE_DIRECTIONS = 5  # the 4 harmonic columns of a circle plus one, and no accidents
MIN_NEW_DIRECTIONS = 3  # a further circle must reach references the others do not
DISTINCT_DIRECTION = 1e-3  # unit references closer than this are one direction
# More distinct references than this is a sphere-like schedule, not a few sweeps (and the
# search over pairs grows as its square).
MAX_DIRECTIONS = 150
# The sweeps must reach at least this share of the poses (each on exactly one circle):
# otherwise the "circles" are a lattice's accidental alignments (a Fibonacci sphere of 200
# has 21 of them, holding 57 of its points), not the table's motion.
MIN_ON_CIRCLES = 0.5


def _distinct(u: np.ndarray) -> np.ndarray:
    """Indices of the first of each group of (nearly) equal unit vectors."""
    keep: list[int] = []
    for i, v in enumerate(u):
        if not keep or np.min(np.linalg.norm(u[keep] - v, axis=1)) > DISTINCT_DIRECTION:
            keep.append(i)
    return np.array(keep, int)


def _canonical(n: np.ndarray) -> np.ndarray:
    n = n / np.linalg.norm(n)
    return n if n[int(np.argmax(np.abs(n)))] > 0 else -n


def sweep_circles(u: np.ndarray) -> list[np.ndarray]:
    """Axes (unit normals, sign canonical) of the great circles the unit references ``u``
    (P,3) were swept along, largest first.

    Every pair of distinct, non-antipodal references spans a candidate plane; a plane is a
    sweep when it holds ≥ ``MIN_CIRCLE_DIRECTIONS`` distinct references. Planes are taken
    greedily by size, each needing ``MIN_NEW_DIRECTIONS`` references not on those already
    taken (two sweeps share at most their two crossing points).
    """
    d = u[_distinct(u)]
    if not MIN_CIRCLE_DIRECTIONS <= len(d) <= MAX_DIRECTIONS:
        return []
    i, j = np.triu_indices(len(d), 1)
    cr = np.cross(d[i], d[j])
    ok = np.linalg.norm(cr, axis=1) > 0.1  # ≥ ~6° apart and not antipodal
    normals = [_canonical(n) for n in cr[ok]]
    found: list[tuple[int, np.ndarray]] = []
    for n in normals:
        if any(abs(float(n @ m)) > 1 - 1e-6 for _, m in found):
            continue
        count = int(np.sum(np.abs(d @ n) < CIRCLE_TOL))
        if count >= MIN_CIRCLE_DIRECTIONS:
            # Refit the normal to all members (the pair's cross product carries their error).
            on = d[np.abs(d @ n) < CIRCLE_TOL]
            n = _canonical(np.linalg.svd(on, full_matrices=False)[2][-1])
            found.append((count, n))
    found.sort(key=lambda c: -c[0])
    taken: list[np.ndarray] = []
    covered = np.zeros(len(d), bool)
    for _, n in found:
        on = np.abs(d @ n) < CIRCLE_TOL
        if int(np.sum(on & ~covered)) >= MIN_NEW_DIRECTIONS:
            taken.append(n)
            covered |= on
    if np.mean(circle_of_pose(u, taken) >= 0) < MIN_ON_CIRCLES:
        return []
    return taken


def circle_of_pose(u_pose: np.ndarray, axes: list[np.ndarray]) -> np.ndarray:
    """(P,) the one circle each pose lies on, −1 for none or several (the poles)."""
    if not axes:
        return np.full(len(u_pose), -1)
    on = np.abs(u_pose @ np.array(axes).T) < CIRCLE_TOL
    out = np.argmax(on, axis=1)
    out[on.sum(axis=1) != 1] = -1
    return out


SHAPE_TILT = 1.0  # grid values of ``turntable_geometry`` (nan: the free turn of each pose)
SHAPE_ENCODER = 2.0
HARMONICS = (1, 2)


def shape_columns(u: np.ndarray, mag: np.ndarray, circle: np.ndarray,
                  axes: list[np.ndarray], shape: float) -> np.ndarray:
    """(N,3,k) change of the specific force (g per rad) for a tilt or an encoder error.

    ``u`` the unit reference of each reading, ``mag`` its |ref| (g), ``circle`` its sweep
    (−1: none, the reading gets zeros). Tilt: ``n`` and ``f × n`` per circle; encoder:
    ``(n × f)·{cos kφ, sin kφ}`` for k in ``HARMONICS`` per circle (module docstring).
    """
    per = 2 if shape == SHAPE_TILT else 2 * len(HARMONICS)
    out = np.zeros((u.shape[0], 3, per * len(axes)))
    for c, n in enumerate(axes):
        rows = circle == c
        if not rows.any():
            continue
        f = u[rows]
        m = mag[rows, None]
        if shape == SHAPE_TILT:
            out[rows, :, per * c] = np.broadcast_to(n, f.shape) * m
            out[rows, :, per * c + 1] = np.cross(f, n) * m
            continue
        a = f[0] - (f[0] @ n) * n
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        phi = np.arctan2(f @ b, f @ a)
        tangent = np.cross(n, f) * m
        for h, k in enumerate(HARMONICS):
            out[rows, :, per * c + 2 * h] = tangent * np.cos(k * phi)[:, None]
            out[rows, :, per * c + 2 * h + 1] = tangent * np.sin(k * phi)[:, None]
    return out


def offset_columns(n_rows: int, circle: np.ndarray, n_circles: int) -> np.ndarray:
    """(N,3,3C) g: a constant offset vector on each sweep circle's readings (others zero).

    The simplest force that moves with the table rather than with the specific force: one
    the table's other axis sets (a cable or connector wound round it) is the same all
    along a sweep of this axis and differs between sweeps. Unlike a rotation, it has a part
    along the reference, and unlike a product of inputs, it does not follow the reference
    along the sweep (issue 22, the unseen ``cable_strain``).
    """
    out = np.zeros((n_rows, 3, 3 * n_circles))
    for c in range(n_circles):
        rows = circle == c
        for a in range(3):
            out[rows, a, 3 * c + a] = 1.0
    return out


def same_tilt_chi2(t: np.ndarray, cov: np.ndarray) -> tuple[float, int]:
    """χ² and dof of "one tilt turns every sweep by the same angle" from per-circle fits.

    ``t`` (C,2): each circle's (t∥, t⊥) of :func:`shape_columns`' tilt, ``cov`` (2C,2C)
    their covariance. Why this is the tilt's physics: a base tilted by the horizontal
    vector t turns a sweep about any horizontal axis a by t∥ = t·a and t⊥ = t·(up × a), so
    √(t∥² + t⊥²) = |t| on every sweep whatever its axis, the sense of that axis or how the
    sensor was mounted (none of which the references give). The magnitudes' spread is
    judged with their delta-method covariance (generalised least squares about their
    common value); C − 1 dof. With fewer than two circles there is nothing to compare.
    """
    n = len(t)
    m = np.linalg.norm(t, axis=1)
    if n < 2 or np.any(m <= 0):
        return 0.0, 0
    J = np.zeros((n, 2 * n))
    for c in range(n):
        J[c, 2 * c:2 * c + 2] = t[c] / m[c]
    V = J @ cov @ J.T
    Vi = np.linalg.pinv(V)
    one = np.ones(n)
    r = float(one @ Vi @ m) / float(one @ Vi @ one)
    d = m - r
    return float(d @ Vi @ d), n - 1
