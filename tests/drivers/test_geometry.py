"""Table angles ↔ reference vector in the sensor frame."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.geometry import angles_for_reference, reference_for_angles


def test_zero_angles_is_z_up() -> None:
    np.testing.assert_allclose(reference_for_angles((0.0, 0.0, 0.0)), [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(reference_for_angles((0.0, 0.0)), [0, 0, 1], atol=1e-15)


def test_axis_convention() -> None:
    # Outer +90° about lab x: sensor +y now points up.
    np.testing.assert_allclose(reference_for_angles((90.0, 0.0, 0.0)), [0, 1, 0], atol=1e-12)
    # Middle +90° about y: sensor −x points up.
    np.testing.assert_allclose(reference_for_angles((0.0, 90.0, 0.0)), [-1, 0, 0], atol=1e-12)
    # Inner axis spins about the plate normal: z-up stays z-up.
    np.testing.assert_allclose(reference_for_angles((0.0, 0.0, 37.0)), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(reference_for_angles((0.0, 0.0, 0.0), g_local=0.98),
                               [0, 0, 0.98])


@pytest.mark.parametrize("n_axes", [2, 3])
def test_roundtrip_random_and_faces(n_axes: int) -> None:
    rng = np.random.default_rng(3)
    faces = [np.array(v, float) for v in
             [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]]
    for v in faces + list(rng.normal(size=(50, 3))):
        angles = angles_for_reference(v, n_axes=n_axes)
        assert len(angles) == n_axes
        np.testing.assert_allclose(reference_for_angles(angles), v / np.linalg.norm(v),
                                   atol=1e-12)


def test_rejects_bad_input() -> None:
    with pytest.raises(ValueError):
        angles_for_reference((0.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        angles_for_reference((0.0, 0.0, 1.0), n_axes=4)
    with pytest.raises(ValueError):
        reference_for_angles((1.0,))


@pytest.mark.parametrize("n_axes", [2, 3])
def test_pose_quaternion_is_the_tables_rotation(n_axes: int) -> None:
    """The recorded pose (docs/recording.md, ``pose_q*``): a unit quaternion, ``qw ≥ 0``,
    whose ``Rᵀ up`` is the reference of the same angles."""
    from scipy.spatial.transform import Rotation

    from drivers.geometry import pose_quaternion

    rng = np.random.default_rng(22)
    corners = [(180.0, 0.0, 0.0), (0.0, 180.0, 0.0), (-90.0, 180.0, 0.0), (90.0, -90.0, 45.0)]
    for angles in [c[:n_axes] for c in corners] + list(rng.uniform(-180, 180, (200, n_axes))):
        q = pose_quaternion(tuple(angles))
        assert len(q) == 4 and q[0] >= 0.0
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12
        R = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
        np.testing.assert_allclose(R.T @ [0.0, 0.0, 1.0], reference_for_angles(angles),
                                   atol=1e-12)
        # the whole rotation, not only its up: intrinsic x-y-z is Rx(a0)·Ry(a1)·Rz(a2)
        full = list(angles) + [0.0] * (3 - n_axes)
        np.testing.assert_allclose(R, Rotation.from_euler("XYZ", full, degrees=True)
                                   .as_matrix(), atol=1e-12)


def test_pose_quaternion_spells_each_rotation_once() -> None:
    from drivers.geometry import pose_quaternion

    assert pose_quaternion((0.0, 0.0, 0.0)) == (1.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(pose_quaternion((90.0, 0.0)),
                               [np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0], atol=1e-15)
    # a half turn about x, reached as +180° and −180°: one quaternion, not its negative
    np.testing.assert_allclose(pose_quaternion((180.0, 0.0)), pose_quaternion((-180.0, 0.0)),
                               atol=1e-15)
    assert pose_quaternion((-180.0, 0.0))[1] > 0.999
    # ... and where the half turn's axis has a component that is zero only in rounding
    np.testing.assert_allclose(pose_quaternion((-90.0, 180.0)), pose_quaternion((-90.0, -180.0)),
                               atol=1e-15)
