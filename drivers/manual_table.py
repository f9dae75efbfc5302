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
from drivers.protocols import Accelerometer, Turntable, TurntableStatus

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


class HandAxisTurntable:
    """A 1-axis motorised stage whose second axis the operator sets by hand.

    Two axes in the 2-axis convention (drivers/geometry.py): axis 0 is the motor (any
    :class:`drivers.protocols.Turntable` of one axis), axis 1 is turned by hand on the
    stage's plate. ``move_to((motor, hand))`` commands the motor and, when the hand
    angle changes, publishes a placement request ("turn the hand axis to 90°") on the
    board. ``read_status`` is in position once the motor is and the operator confirmed,
    and (with an accelerometer) a short capture shows the sensor static within 15° of
    the asked direction, as :class:`ManualTurntable` checks a hand placement.
    """

    def __init__(self, motor: Turntable, board: Any, accelerometer: Accelerometer | None = None,
                 *, check_samples: int = 64, noise_g: float = ADXL355_NOISE_G) -> None:
        if motor.n_axes != 1:
            raise ValueError(f"the motorised stage has {motor.n_axes} axes, expected 1")
        self.motor = motor
        self.board = board
        self.accelerometer = accelerometer
        self.check_samples = check_samples
        self.noise_g = noise_g
        self._hand_deg: float | None = None  # None: the operator was never asked
        self._asked: tuple[float, float] | None = None
        self._placed = False
        self.rejections: list[str] = []

    @property
    def n_axes(self) -> int:
        return 2

    @property
    def safe_angles_deg(self) -> tuple[float, ...]:
        rest = tuple(getattr(self.motor, "safe_angles_deg", (0.0,)))
        return (*rest, self._hand_deg or 0.0)

    async def move_to(self, angles_deg: tuple[float, ...]) -> None:
        motor_deg, hand_deg = (float(a) for a in angles_deg)
        await self.motor.move_to((motor_deg,))
        self._asked = (motor_deg, hand_deg)
        if self._hand_deg is not None and hand_deg == self._hand_deg and self._placed:
            return  # the hand axis stays: only the motor moves
        asked = self.board.publish(reference_for_angles(self._asked),
                                   instruction=_hand_instruction(hand_deg))
        if asked is None:  # no campaign to ask in (rig check --move): only the motor moves,
            self._placed = True  # the hand axis is left as it is and asked in a campaign
            return
        self._hand_deg, self._placed = hand_deg, False

    async def read_status(self) -> TurntableStatus:
        st = await self.motor.read_status()
        hand = self._hand_deg if self._hand_deg is not None else 0.0
        angles = (st.angles_deg[0], hand)
        if st.faults or not st.in_position or self._placed or self._asked is None:
            done = st.in_position and (self._placed or self._asked is None)
            return TurntableStatus(angles, done, st.moving, st.faults, st.homed)
        if self.board.state() != "confirmed":
            return TurntableStatus(angles, False, False, (), st.homed)
        ref = reference_for_angles(self._asked)
        if self.accelerometer is not None:
            acq = await self.accelerometer.acquire(self.check_samples)
            check = check_placement(np.asarray(acq.mean_g), np.asarray(acq.sd_g), ref,
                                    self.noise_g)
            if not check.ok:
                self.rejections.append(check.reason)
                self.board.publish(ref, reason=check.reason,
                                   instruction=_hand_instruction(hand))
                return TurntableStatus(angles, False, False, (), st.homed)
        self.board.accept()
        self._placed = True
        return TurntableStatus(angles, True, False, (), st.homed)

    async def stop(self) -> None:
        await self.motor.stop()

    async def park(self) -> str:
        """The motor's park; the hand axis stays where the operator last set it."""
        said = await self.motor.park()
        return f"{said}; the hand axis stays where it was set by hand"

    async def close(self) -> None:
        close = getattr(self.motor, "close", None)
        if close is not None:
            await close()


def _hand_instruction(hand_deg: float) -> str:
    return (f"turn the hand axis to {hand_deg:g}° and lock it "
            "(the motorised axis moves by itself)")
