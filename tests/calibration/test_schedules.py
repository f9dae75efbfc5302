"""Position schedules and their identifiability."""

import numpy as np
import pytest

from calibration import schedules


def test_table1_is_three_great_circles_of_eight_at_45_degrees() -> None:
    t = schedules.table1()
    assert t.shape == (24, 3)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0)
    # Each circle of 8 has one axis fixed at zero (z, y, x) and 45° between neighbours.
    for block, zero_axis in zip(np.split(t, 3), (2, 1, 0), strict=True):
        np.testing.assert_allclose(block[:, zero_axis], 0.0, atol=1e-15)
        cos = np.sum(block * np.roll(block, -1, axis=0), axis=1)
        np.testing.assert_allclose(cos, np.cos(np.deg2rad(45.0)), atol=1e-12)
    # Every axis is visited pointing up and down.
    for k in range(3):
        assert t[:, k].max() == pytest.approx(1.0) and t[:, k].min() == pytest.approx(-1.0)


@pytest.mark.parametrize("n", [1, 12, 24, 1296])
def test_sphere_points_are_unit_and_spread(n: int) -> None:
    s = schedules.sphere(n)
    assert s.shape == (n, 3)
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0)
    if n >= 24:
        assert np.linalg.norm(s.mean(axis=0)) < 0.05  # no hemisphere favoured
        assert len({tuple(np.round(p, 9)) for p in s}) == n  # all distinct


def test_sphere_refuses_zero() -> None:
    with pytest.raises(ValueError, match="n >= 1"):
        schedules.sphere(0)


def test_get_schedule_by_name() -> None:
    assert schedules.get_schedule("Table1").shape == (24, 3)
    assert schedules.get_schedule("six").shape == (6, 3)
    assert schedules.get_schedule("ferraris").shape == (6, 3)
    assert schedules.get_schedule("sphere1296").shape == (1296, 3)
    assert schedules.get_schedule("table1+cube14").shape == (38, 3)
    with pytest.raises(ValueError, match="unknown position schedule"):
        schedules.get_schedule("octahedron")


def test_table4_counts() -> None:
    assert schedules.TABLE4_NOP[0] == 1296 and schedules.TABLE4_NOP[-1] == 12
    assert list(schedules.TABLE4_NOP) == sorted(schedules.TABLE4_NOP, reverse=True)


@pytest.mark.parametrize("name", ["table1", "six", "cube14", "sphere24"])
def test_reference_mode_determines_all_twelve(name: str) -> None:
    ident = schedules.identifiability(schedules.get_schedule(name), "reference")
    assert ident.ok and ident.rank == 12


@pytest.mark.parametrize("name", ["table1", "cube14", "sphere24"])
def test_norm_mode_determines_nine_and_never_the_rotation(name: str) -> None:
    ident = schedules.identifiability(schedules.get_schedule(name), "norm")
    assert ident.rank == 9
    assert set(ident.undetermined) == {"mx", "my", "mz"}
    assert not ident.ok


def test_six_position_norm_mode_loses_the_non_orthogonality() -> None:
    ident = schedules.identifiability(schedules.six_position(), "norm")
    assert ident.rank == 6
    assert {"ayx", "azx", "azy"} <= set(ident.undetermined)


def test_one_great_circle_is_not_enough_for_reference_mode() -> None:
    ident = schedules.identifiability(schedules.table1()[:8], "reference")
    assert ident.rank < 12 and ident.undetermined


def test_identifiability_rejects_unknown_mode() -> None:
    with pytest.raises(ValueError, match="mode"):
        schedules.identifiability(schedules.table1(), "magic")


def test_tilt_fixture_adds_a_wedge_ring_that_determines_norm_mode() -> None:
    from calibration.schedules import get_schedule, identifiability, tilt_fixture

    ref = tilt_fixture()
    assert ref.shape == (22, 3) and np.allclose(np.linalg.norm(ref, axis=1), 1.0)
    ring = ref[6:]
    assert np.allclose(np.abs(ring[:, 2]), np.cos(np.radians(45.0)))
    assert identifiability(ref, "norm").undetermined == ("mx", "my", "mz")
    assert identifiability(ref, "reference").ok
    assert np.allclose(get_schedule("tilt30")[6, 2], np.cos(np.radians(30.0)))
    assert np.allclose(get_schedule("tilt"), ref)
    with pytest.raises(ValueError, match="tilt<DEG>"):
        get_schedule("tilt95")
