"""In-process fakes of the three device protocols, with just enough physics.

Time comes from the injected clock and state is integrated lazily on each
call (no background task), so a VirtualClock runs a many-hour campaign in a
second. The chamber's working setpoint ramps at the commanded rate, the air
(PV) lags it, the die lags the air; the sensor reads the die through a
constant offset plus noise; the table reaches a commanded pose after a slew.
The thermal steps are the rig plant's (``calibration.thermal_plant``), not a copy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calibration.thermal_plant import lag_step, rate_limited
from drivers.clock import Clock
from drivers.faults import DeviceTimeout
from drivers.protocols import (
    Acquisition,
    ChamberStatus,
    SensorIdentity,
    TurntableStatus,
)
from service.engine.rigs import RigDevices
from simulators.truth import SensorTruth

DT_S = 5.0  # integration sub-step


@dataclass
class Physics:
    clock: Clock
    air_tau_s: float = 120.0
    die_tau_s: float = 600.0
    setpoint_c: float = 23.0
    wsp_c: float = 23.0
    air_c: float = 23.0
    die_c: float = 23.0
    ramp_c_per_min: float = 1.0
    running: bool = False
    t_s: float = 0.0
    drift_c: float = 0.0  # added to the air target (tests make the chamber never settle)

    def advance(self) -> None:
        now = self.clock.now()
        while self.t_s < now:
            dt = min(DT_S, now - self.t_s)
            # The rig's plant (calibration/thermal_plant.py), as the twins step it.
            if self.running:
                step = self.ramp_c_per_min / 60.0 * dt if self.ramp_c_per_min > 0 else math.inf
                self.wsp_c = rate_limited(self.wsp_c, self.setpoint_c, step)
            target = self.wsp_c + self.drift_c * math.sin(self.t_s / 400.0)
            self.air_c = lag_step(self.air_c, target, dt, self.air_tau_s)
            self.die_c = lag_step(self.die_c, self.air_c, dt, self.die_tau_s)
            self.t_s += dt


@dataclass
class Faults:
    """Deterministic fault injection: a failure probability and outage windows (clock s)."""

    p_fail: float = 0.0
    outages: list[tuple[float, float, str]] = field(default_factory=list)  # (from, to, device)
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(7))
    calls: int = 0
    raised: int = 0

    def maybe_raise(self, device: str, now_s: float) -> None:
        self.calls += 1
        for lo, hi, dev in self.outages:
            if dev == device and lo <= now_s < hi:
                self.raised += 1
                raise DeviceTimeout(device, f"no reply (outage {lo:.0f}-{hi:.0f} s)")
        if self.p_fail and self.rng.random() < self.p_fail:
            self.raised += 1
            raise DeviceTimeout(device, "no reply (injected)")


class FakeChamber:
    def __init__(self, ph: Physics, faults: Faults) -> None:
        self.ph, self.faults = ph, faults
        self.setpoints_c: list[float] = []

    @property
    def range_c(self) -> tuple[float, float]:
        return (-70.0, 180.0)

    def _io(self) -> None:
        self.faults.maybe_raise("chamber", self.ph.clock.now())
        self.ph.advance()

    async def read_status(self) -> ChamberStatus:
        self._io()
        p = self.ph
        return ChamberStatus(p.air_c, p.setpoint_c, p.wsp_c, p.ramp_c_per_min, p.running)

    async def set_setpoint(self, setpoint_c: float) -> None:
        self._io()
        self.ph.setpoint_c = setpoint_c
        self.setpoints_c.append(setpoint_c)

    async def set_ramp_rate(self, ramp_c_per_min: float) -> None:
        self._io()
        self.ph.ramp_c_per_min = ramp_c_per_min

    async def run(self) -> None:
        self._io()
        self.ph.running = True

    async def stop(self) -> None:
        self._io()
        self.ph.running = False

    async def park(self, setpoint_c: float | None = None) -> str:
        """The shipped maps' safe state: 23 °C, the controller left running."""
        target_c = 23.0 if setpoint_c is None else setpoint_c
        await self.set_setpoint(target_c)
        return f"setpoint {target_c:g} °C"


class FakeTurntable:
    SLEW_S = 4.0

    def __init__(self, clock: Clock, faults: Faults) -> None:
        self.clock, self.faults = clock, faults
        self.angles: tuple[float, ...] = (0.0, 0.0)  # what the table reports
        self.physical_angles: tuple[float, ...] = (0.0, 0.0)  # where it stands (the sensor's)
        self.arrive_s = 0.0
        self.moves = 0
        self.stops = 0
        # Moves (1-based numbers) that silently land at home: reported as commanded.
        self.silent_home_moves: set[int] = set()

    @property
    def n_axes(self) -> int:
        return 2

    async def move_to(self, angles_deg: tuple[float, ...]) -> None:
        self.faults.maybe_raise("turntable", self.clock.now())
        self.angles = tuple(angles_deg)
        self.arrive_s = self.clock.now() + self.SLEW_S
        self.moves += 1
        home = tuple(0.0 for _ in angles_deg)
        self.physical_angles = home if self.moves in self.silent_home_moves else self.angles

    async def read_status(self) -> TurntableStatus:
        self.faults.maybe_raise("turntable", self.clock.now())
        there = self.clock.now() >= self.arrive_s
        return TurntableStatus(self.angles, in_position=there, moving=not there)

    async def stop(self) -> None:
        self.stops += 1
        self.arrive_s = min(self.arrive_s, self.clock.now())

    async def park(self) -> str:
        await self.stop()
        await self.move_to((0.0, 0.0))
        return "stopped, sent to (0, 0)°"


def angles_for(ref: np.ndarray) -> tuple[float, float]:
    """Fake geometry: (azimuth, elevation) of the gravity direction, exactly invertible."""
    x, y, z = (float(v) for v in ref)
    return (math.degrees(math.atan2(y, x)), math.degrees(math.asin(max(-1.0, min(1.0, z)))))


def ref_for(angles: tuple[float, ...]) -> np.ndarray:
    az, el = (math.radians(a) for a in angles)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


class FakeAccelerometer:
    ODR_HZ = 62.5

    def __init__(self, ph: Physics, table: FakeTurntable, faults: Faults, seed: int = 1) -> None:
        self.ph, self.table, self.faults = ph, table, faults
        self.truth = SensorTruth.adxl355_typical(seed=seed)
        self.rng = np.random.default_rng(seed)
        self.acquisitions = 0
        self.bad_captures = 0  # the next N captures come back noisy (quality re-measure tests)

    async def identify(self) -> SensorIdentity:
        return SensorIdentity("ADXL355", self.truth.serial, "fake")

    async def configure(self, range_g: float, odr_hz: float) -> None:
        self.faults.maybe_raise("accelerometer", self.ph.clock.now())

    async def acquire(self, n_samples: int) -> Acquisition:
        self.faults.maybe_raise("accelerometer", self.ph.clock.now())
        duration_s = n_samples / self.ODR_HZ
        await self.ph.clock.sleep(duration_s)
        self.ph.advance()
        self.acquisitions += 1
        ref = ref_for(self.table.physical_angles)
        s = self.truth.sample_g(ref, self.ph.die_c, n_samples, self.rng)
        if self.bad_captures > 0:
            self.bad_captures -= 1
            s = s + self.rng.normal(0, 0.01, s.shape)
        temps = self.truth.temperature_samples_c(self.ph.die_c, n_samples, self.rng)
        return Acquisition(
            mean_g=tuple(float(v) for v in s.mean(axis=0)),
            sd_g=tuple(float(v) for v in s.std(axis=0, ddof=1)) if n_samples > 1 else (0, 0, 0),
            n=n_samples, sensor_c=float(temps.mean()),
            # span of a smoothed channel: the raw channel's noise is not die movement
            sensor_c_span=_smoothed_span_c(temps),
            saturated=bool(np.any(np.abs(s) >= self.truth.range_g)),
            duration_s=duration_s,
        )


def _smoothed_span_c(temps: np.ndarray) -> float:
    """Span of a smoothed channel: the raw channel's noise is not die movement."""
    q = temps.size // 4
    return float(abs(temps[-q:].mean() - temps[:q].mean())) if q >= 2 else 0.0


@dataclass
class FakeRig:
    devices: RigDevices
    physics: Physics
    chamber: FakeChamber
    turntable: FakeTurntable
    accelerometer: FakeAccelerometer
    faults: Faults


def make_fake_rig(clock: Clock, faults: Faults | None = None, **physics: float) -> FakeRig:
    faults = faults or Faults()
    ph = Physics(clock=clock, **physics)
    ch = FakeChamber(ph, faults)
    tt = FakeTurntable(clock, faults)
    acc = FakeAccelerometer(ph, tt, faults)
    return FakeRig(RigDevices(ch, tt, acc, angles_for), ph, ch, tt, acc, faults)
