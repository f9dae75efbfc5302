"""A turntable that is a person: the ``manual`` driver for hand-placed fixtures.

Implements :class:`drivers.protocols.Turntable` for labs without a turntable
(docs/manual-fixtures.md). ``move_to`` moves nothing: it turns the commanded
angles back into the scheduled direction of gravity in the sensor frame
(:func:`drivers.geometry.reference_for_angles`) and publishes a placement
request ("face +z up, x towards the door" plus a sketch) on a
:class:`service.engine.placement.PlacementBoard`. ``read_status`` reports
``in_position`` only once the operator confirmed (REST or CLI) *and* a short
capture shows the sensor static and within 15° of the asked direction
(:func:`calibration.placement.check_placement`); otherwise the request is
re-issued with the reason.

The driver never waits itself: the engine polls ``read_status`` on its
injected clock through the device guard, which honours pause and abort before
every call (service/engine/runner.py ``_move_to``), so a wait for the operator
is interruptible like any table move. A campaign on a manual rig should set a
``move_timeout_s`` long enough for a person (docs/manual-fixtures.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.placement import check_placement
from drivers.geometry import reference_for_angles
from drivers.protocols import Accelerometer, TurntableStatus

ADXL355_NOISE_G = 0.2e-3  # ~25 µg/√Hz over the ~60 Hz noise bandwidth at 125 Hz ODR, g rms


class ManualTurntable:
    """Placement requests instead of motors; see the module docstring."""

    def __init__(self, board: Any, accelerometer: Accelerometer | None = None, *,
                 n_axes: int = 3, check_samples: int = 64,
                 noise_g: float = ADXL355_NOISE_G) -> None:
        self.board = board  # PlacementBoard (or anything with publish/state/accept)
        self.accelerometer = accelerometer
        self._n_axes = n_axes
        self.check_samples = check_samples
        self.noise_g = noise_g
        self._angles: tuple[float, ...] | None = None  # None: nothing asked yet
        self._ref: np.ndarray | None = None
        self._placed = True
        self.rejections: list[str] = []  # reasons of re-issued requests, newest last

    @property
    def n_axes(self) -> int:
        return self._n_axes

    async def move_to(self, angles_deg: tuple[float, ...]) -> None:
        """Publish the placement request for these angles (kept as is if already open)."""
        angles = tuple(float(a) for a in angles_deg)
        if angles == self._angles and self._placed:
            return  # already placed there (e.g. the engine's re-command after a suspension)
        self._angles = angles
        self._ref = reference_for_angles(angles)
        self._placed = False
        self.board.publish(self._ref)

    async def read_status(self) -> TurntableStatus:
        angles = self._angles or tuple(0.0 for _ in range(self._n_axes))
        if self._placed or self._ref is None:
            return TurntableStatus(angles, in_position=True, moving=False)
        if self.board.state() != "confirmed":
            return TurntableStatus(angles, in_position=False, moving=False)
        if self.accelerometer is not None:
            acq = await self.accelerometer.acquire(self.check_samples)
            check = check_placement(np.asarray(acq.mean_g), np.asarray(acq.sd_g), self._ref,
                                    self.noise_g)
            if not check.ok:
                self.rejections.append(check.reason)
                self.board.publish(self._ref, reason=check.reason)
                return TurntableStatus(angles, in_position=False, moving=False)
        self.board.accept()
        self._placed = True
        return TurntableStatus(angles, in_position=True, moving=False)

    async def stop(self) -> None:
        """Nothing moves; the open request stays open."""

    async def park(self) -> str:
        """Nothing to move: the table is a person, and the sensor stays where the operator
        last placed it. No request is published (a campaign that ended cannot have a
        placement confirmed, so a last "home" request would only wait for ever)."""
        return "nothing to move (hand-placed fixture: the sensor stays where it was placed)"
