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
