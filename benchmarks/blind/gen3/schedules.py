"""Orientations (unit gravity directions in the sensor frame) for gen3 (issue 22): the seed
paper's Table 1 (three circles of 8 positions, 45° apart, about x, y and z), the 6 faces,
sparse 12 (icosahedron vertices) and 18 (faces and cube edges), and a random sphere."""

from __future__ import annotations

import numpy as np


def table1() -> np.ndarray:
    """Table 1's 24 positions: gravity swept in 45° steps in the y–z, x–z and x–y planes."""
    a = np.deg2rad(np.arange(8) * 45.0)
    c, s, z = np.cos(a), np.sin(a), np.zeros(8)
    return np.vstack([np.c_[z, s, c], np.c_[s, z, c], np.c_[c, s, z]])


def faces() -> np.ndarray:
    """The six axis-aligned faces."""
    return np.vstack([np.eye(3), -np.eye(3)])


def cube_edges() -> np.ndarray:
    """The 12 directions to the midpoints of a cube's edges."""
    out = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        for si in (1.0, -1.0):
            for sj in (1.0, -1.0):
                v = np.zeros(3)
                v[i], v[j] = si, sj
                out.append(v / np.sqrt(2.0))
    return np.array(out)


def sparse12(rng: np.random.Generator) -> np.ndarray:
    """The 12 vertices of an icosahedron, turned at random (oblique positions only)."""
    p = (1.0 + np.sqrt(5.0)) / 2.0
    v = []
    for a in (1.0, -1.0):
        for b in (p, -p):
            v += [(0.0, a, b), (a, b, 0.0), (b, 0.0, a)]
    v = np.array(v) / np.sqrt(1.0 + p * p)
    return v @ random_rotation(rng).T


def sparse18() -> np.ndarray:
    """Faces and cube edges: 18 positions."""
    return np.vstack([faces(), cube_edges()])


def sphere(rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` directions uniform on the sphere."""
    v = rng.standard_normal((count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (QR of a Gaussian matrix, sign-fixed)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def small_rotation(rng: np.random.Generator, max_rad: float) -> np.ndarray:
    """A rotation by a random angle in [0, max_rad] about a random axis (Rodrigues); the
    re-seating of a hand fixture (issue 22: ≤ 0.5 mrad)."""
    axis = sphere(rng, 1)[0]
    angle = rng.uniform(0.0, max_rad)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


SCHEDULE_NAMES = ("table1", "faces", "sparse12", "sparse18", "sphere")
HAND_SCHEDULES = ("faces", "sparse12", "sparse18")  # a fixture that can be set by hand


def schedule(name: str, rng: np.random.Generator) -> np.ndarray:
    """The directions of the named schedule (``sphere`` draws 30–48 of them)."""
    if name == "table1":
        return table1()
    if name == "faces":
        return faces()
    if name == "sparse12":
        return sparse12(rng)
    if name == "sparse18":
        return sparse18()
    if name == "sphere":
        return sphere(rng, int(rng.integers(30, 49)))
    raise ValueError(f"unknown schedule {name!r}")
