"""The table's commanded pose per reading: the ``pose_q*`` columns (docs/recording.md).

A reference ``ref_*`` says where gravity lies in the sensor frame, not how the table holds
the sensor about it: two poses with one reference differ by a turn about gravity. A tilted
table base turns gravity by an angle constant in the *lab* frame, so its effect on each
reading is ``Rᵀ·(T − I)·up``, which needs the pose R (issue 22). soakcal's engine writes
the pose it commanded as a unit quaternion (scalar first) of the rotation R from sensor to
lab coordinates, lab z up, so that ``ref = |g|·Rᵀ·(0, 0, 1)``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from calibration.errors import RecordingError
from calibration.recording import POSE_COLUMNS, Recording, optional_number_column

# A pose and its reference are written from one commanded pose: soakcal's agree to
# rounding (a hand axis' step included: the row's reference is the step's). Beyond this the
# two columns describe different orientations (one of them mistyped or from another
# convention) and neither can be trusted; 1° leaves room for another writer's rounding.
POSE_REF_TOL_DEG = 1.0
UNIT_TOL = 1e-3  # |q| − 1 beyond this: not a rotation written to the column's precision


def read_poses(rec: Recording) -> np.ndarray | None:
    """(N, 4) unit quaternions (w, x, y, z) of every reading's pose, or None where the
    recording has no pose on some reading (a hand-placed fixture, an older export): a pose
    known for part of a recording cannot be told from the rest.

    Kept as quaternions, not (N, 3, 3) matrices: 32 bytes a reading against 72 on a long
    recording (:func:`pose_rows` gives the matrix rows by blocks). A cell that is not a
    number, a quaternion off unit length, or a pose that puts gravity more than
    :data:`POSE_REF_TOL_DEG` from the row's ``ref_*`` is an error naming the line and
    column: a confident answer built on it would be wrong."""
    cols = [optional_number_column(rec, c, "a pose quaternion component")
            for c in POSE_COLUMNS]
    if any(c is None for c in cols):
        return None
    q = np.column_stack(cols)
    if not np.all(np.isfinite(q)):
        return None
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > UNIT_TOL)
    if bad.size:
        i = int(bad[0])
        raise RecordingError(rec.path, i + 2, "pose_qw",
                             f"pose_qw..pose_qz have length {norm[i]:.6g}, not 1: a pose "
                             "is a unit quaternion (scalar first)")
    q /= norm[:, None]
    ref = rec.ref_g
    if ref is not None:
        u = ref / np.maximum(np.linalg.norm(ref, axis=1, keepdims=True), 1e-300)
        g = pose_rows(q, (2,))[:, :, 0]  # Rᵀ·up: gravity in the sensor frame
        off = np.degrees(np.arccos(np.clip(np.sum(g * u, axis=1), -1.0, 1.0)))
        worst = int(np.argmax(off))
        if off[worst] > POSE_REF_TOL_DEG:
            raise RecordingError(
                rec.path, worst + 2, "pose_qw",
                f"the pose puts gravity at ({g[worst, 0]:+.3f}, {g[worst, 1]:+.3f}, "
                f"{g[worst, 2]:+.3f}) in the sensor frame, {off[worst]:.1f}° from ref_* "
                f"({u[worst, 0]:+.3f}, {u[worst, 1]:+.3f}, {u[worst, 2]:+.3f}); both are "
                "written from one commanded pose (ref = Rᵀ·up): check the pose columns' "
                "order (w, x, y, z) and frame (sensor to lab)")
    return q


POSE_BLOCK = 65_536  # readings converted at a time (an (n, 3, 3) block of 4.7 MB)


def pose_rows(q: np.ndarray, rows: tuple[int, ...]) -> np.ndarray:
    """(N, 3, len(rows)) the rows ``rows`` of each pose's R (sensor to lab): row k of R is
    ``Rᵀ·e_k``, lab axis k seen in the sensor frame. By blocks of :data:`POSE_BLOCK`
    readings, so no (N, 3, 3) array is held."""
    out = np.empty((q.shape[0], 3, len(rows)))
    for i in range(0, q.shape[0], POSE_BLOCK):
        R = Rotation.from_quat(q[i:i + POSE_BLOCK][:, [1, 2, 3, 0]]).as_matrix()
        out[i:i + POSE_BLOCK] = R[:, list(rows), :].transpose(0, 2, 1)
    return out


# |qw| below this is a half turn's rounding (±6e-17 as the angle came as +180° or −180°):
# taken as 0, so that the vector part's sign, not the rounding, picks the spelling
HALF_TURN_QW = 1e-12


def pose_quaternion(R: np.ndarray) -> np.ndarray:
    """(…, 4) unit quaternions (w, x, y, z) of rotations ``R`` (…, 3, 3) from sensor to
    lab: what the ``pose_q*`` columns hold. One spelling per rotation, so equal poses give
    equal cells: ``qw ≥ 0``, and at a half turn (``qw`` 0 in rounding) the first of ``qx,
    qy, qz`` not zero in rounding is positive. scipy's conversion (scalar last in every
    scipy ≥ 1.11, reordered here)."""
    xyzw = Rotation.from_matrix(np.asarray(R, float).reshape(-1, 3, 3)).as_quat()
    q = xyzw[:, [3, 0, 1, 2]]
    q[:, 0] = np.where(np.abs(q[:, 0]) < HALF_TURN_QW, 0.0, q[:, 0])
    big = np.abs(q) >= HALF_TURN_QW
    lead = np.where(big.any(axis=1), q[np.arange(len(q)), np.argmax(big, axis=1)], 1.0)
    q = q * np.where(lead < 0.0, -1.0, 1.0)[:, None] + 0.0  # + 0.0: no −0.0 cells
    return q.reshape(np.shape(R)[:-2] + (4,))


def lab_tilt_columns(q: np.ndarray, mag_g: np.ndarray) -> np.ndarray:
    """(N, 3, 2) change of the specific force per radian of base tilt about lab x and y,
    for poses ``q`` (:func:`read_poses`).

    The tilted base turns lab up to ``Rx(tx)·Ry(ty)·up ≈ (ty, −tx, 1)``, so the force in
    the sensor frame moves by ``|g|·(ty·Rᵀe_x − tx·Rᵀe_y)``: across the reference always
    (Rᵀe_x, Rᵀe_y ⊥ Rᵀe_z), by an amount and direction each pose's heading sets."""
    xy = pose_rows(q, (0, 1)) * np.asarray(mag_g, float)[:, None, None]
    return np.stack([-xy[:, :, 1], xy[:, :, 0]], axis=2)
