"""How well a recording's reference directions are known: the ``ref_tol_deg`` column.

A turntable sets each orientation to arc-seconds; a sensor put on a cube face or a
tilt fixture by hand sits a degree or so off the labelled direction. A recording
says its references are hand-placed with the optional column ``ref_tol_deg``: the
one-sigma angle (degrees, > 0) by which the true direction of gravity may differ
from ``ref_*`` at that row. Absent column: the references are exact (the seed's
turntable case). The column must then be filled on every row with a reference;
``soakcal import --format ferraris`` writes it (:data:`HAND_HELD_TOL_DEG`).

The fit uses it as a per-position orientation prior (:func:`calibration.fit.fit_reference`
with ``ref_tol_rad``): |g| keeps its full weight, the direction only decides what
|g| cannot see. docs/fit-honesty.md describes the contract and the evidence.

The same module holds the pose geometry of a capture: the plain-language placement
for a reference direction (:func:`instruction_for`, :func:`sketch_for`) and the check
that a static capture reads gravity from the direction its label claims
(:func:`check_pose`, :func:`check_placement`) — used by the manual-table driver
and by the engine before it stores any capture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.errors import RecordingError
from calibration.recording import Recording, optional_number_column

REF_TOL_COLUMN = "ref_tol_deg"
# A box held against a table edge or a printed cube face: placement within ~1-2°.
# The fit's result hardly depends on the value as long as it is far above σ/g
# (docs/fit-honesty.md: 0.1° … 5° give the same |g| errors on imucal-ferraris).
HAND_HELD_TOL_DEG = 2.0


def reference_tolerance_rad(rec: Recording) -> np.ndarray | None:
    """Per-row orientation uncertainty (rad) from ``ref_tol_deg``, or None if exact.

    Raises :class:`RecordingError` (file, line, column) for a cell that is not a
    positive number, or an empty cell while others are filled.
    """
    values = optional_number_column(rec, REF_TOL_COLUMN, "degrees")
    if values is None:
        return None
    filled = np.isfinite(values)
    if not filled.any():
        return None
    bad = np.flatnonzero(~filled | (values <= 0) | (values >= 90))
    if bad.size:
        i = int(bad[0])
        what = "empty" if not filled[i] else f"{values[i]:g}"
        raise RecordingError(
            rec.path, i + 2, REF_TOL_COLUMN,
            f"{what}: the placement uncertainty must be a number of degrees in (0, 90) on "
            "every row once the column is used")
    return np.radians(values)


# --- pose geometry: where gravity is, against where it was asked -----------------------
AXES = ("x", "y", "z")
FACE_UP_DEG = 80.0  # an axis this far above the horizontal: "face +z up"
MAX_ANGLE_DEG = 15.0  # measured gravity further than this from the asked direction: re-ask
STATIC_FACTOR = 5.0  # capture sd above this many times the sensor noise: still moving


def _signed(axis: int, sign: float) -> str:
    return f"{'+' if sign >= 0 else '-'}{AXES[axis]}"


def elevations_deg(ref_g: np.ndarray) -> np.ndarray:
    """Elevation of each sensor axis above the horizontal, degrees: asin(f_i/|f|)."""
    f = np.asarray(ref_g, float)
    return np.degrees(np.arcsin(np.clip(f / np.linalg.norm(f), -1.0, 1.0)))


def instruction_for(ref_g: np.ndarray) -> str:
    """The plain-language placement for a specific-force direction (sensor frame).

    A face position (one axis within 10° of vertical) reads "face +z up"; the
    heading about the vertical is free (gravity does not see it) and is
    suggested only so that the operator repeats it. Oblique positions (cube
    diagonals, tilt fixture) name each axis' elevation.
    """
    el = elevations_deg(ref_g)
    main = int(np.argmax(np.abs(el)))
    if abs(el[main]) >= FACE_UP_DEG:
        side = (main + 1) % 3
        return (f"face {_signed(main, el[main])} up, {AXES[side]} towards the door "
                f"(any heading works: gravity does not see it)")
    parts = ", ".join(f"{AXES[i]} {el[i]:+.0f}°" for i in range(3))
    return (f"oblique: rest the sensor so that its axes rise above the horizontal by {parts} "
            f"(most upward: {_signed(main, el[main])})")


def sketch_for(ref_g: np.ndarray) -> str:
    """A small ASCII side view: the upward sensor axis over the bench."""
    el = elevations_deg(ref_g)
    main = int(np.argmax(np.abs(el)))
    up = _signed(main, el[main])
    side = AXES[(main + 1) % 3]
    tilt = "" if abs(el[main]) >= FACE_UP_DEG else f" (tilted: {up} {el[main]:+.0f}° up)"
    return "\n".join([
        f"      ^ {up} up{tilt}",
        "      |",
        "   +-----+",
        f"   | DUT |--> {side} towards the door",
        "   +-----+",
        "  =========  bench / fixture",
    ])


@dataclass(frozen=True)
class PlacementCheck:
    """Outcome of :func:`check_placement`; ``reason`` is what the operator reads when not ok."""

    ok: bool
    angle_deg: float  # between the measured and the asked direction
    static: bool
    reason: str = ""


def check_placement(mean_g: np.ndarray, sd_g: np.ndarray, ref_g: np.ndarray, noise_g: float,
                    *, max_angle_deg: float = MAX_ANGLE_DEG,
                    static_factor: float = STATIC_FACTOR) -> PlacementCheck:
    """Is the sensor static and roughly where asked?

    Static: every axis' capture sd below ``static_factor`` × ``noise_g`` (the
    sensor's own noise per sample, g). Where asked: :func:`check_pose` (a hand
    placement is good to a few degrees; the fit carries that as ``ref_tol_deg``,
    docs/fit-honesty.md — this check only catches a wrong face).
    """
    sd_max = float(np.max(np.asarray(sd_g, float)))
    if sd_max > static_factor * noise_g:
        return PlacementCheck(False, direction_error_deg(mean_g, ref_g), False, (
            f"the sensor is moving (sd {sd_max * 1e3:.2f} mg against {noise_g * 1e3:.3f} mg "
            f"noise): let it rest, then confirm again"))
    return check_pose(mean_g, ref_g, max_angle_deg=max_angle_deg)


def direction_error_deg(mean_g: np.ndarray, ref_g: np.ndarray) -> float:
    """Angle between the measured specific force and the reference direction, degrees."""
    m = np.asarray(mean_g, float)
    r = np.asarray(ref_g, float)
    cos = float(np.dot(m, r) / (np.linalg.norm(m) * np.linalg.norm(r)))
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def check_pose(mean_g: np.ndarray, ref_g: np.ndarray, *,
               max_angle_deg: float = MAX_ANGLE_DEG) -> PlacementCheck:
    """Does a static capture read gravity from the direction its pose claims?

    The one pose check, of a hand placement (:func:`check_placement`) and of every
    capture the engine stores (a table that silently stopped elsewhere). An
    uncalibrated sensor's direction is off by its zero-g offset and misalignment
    (a few degrees for an ADXL355-class part: 75 mg over temperature is 4.3°), far
    inside ``max_angle_deg``; a wrong face or pose is 45° or more away on the
    shipped schedules. ``reason`` says which axis is where, for the operator.
    """
    angle_deg = direction_error_deg(mean_g, ref_g)
    if angle_deg < max_angle_deg:
        return PlacementCheck(True, angle_deg, True)
    el_asked, el_seen = elevations_deg(np.asarray(ref_g, float)), elevations_deg(mean_g)
    main = int(np.argmax(np.abs(el_asked)))
    asked = "up" if el_asked[main] > 0 else "down"
    seen = "up" if el_seen[main] > 30 else "down" if el_seen[main] < -30 else "sideways"
    seen_main = int(np.argmax(np.abs(el_seen)))
    if seen != asked:
        hint = (f"{AXES[main]} looks {seen}, not {asked} "
                f"({_signed(seen_main, el_seen[seen_main])} is up now): turn the cube")
    else:
        hint = f"{AXES[main]} is {asked} but tilted: seat the fixture flat"
    return PlacementCheck(False, angle_deg, True,
                          f"{hint} ({angle_deg:.0f}° from the asked direction, "
                          f"limit {max_angle_deg:.0f}°)")
