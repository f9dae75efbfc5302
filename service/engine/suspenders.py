"""Suspenders: conditions that hold a campaign until they clear, installed on the engine.

Like bluesky's suspenders, each watches what the engine reads anyway and,
when tripped, says why; the engine then holds (chamber at its setpoint, no
readings taken), waits until the condition has stayed clear for
``clear_s``, and resumes -- or fails the campaign once the condition lasted
``limit_s`` of real time. ``restart_soak`` says whether the physics needs the
soak redone before measuring again: a chamber that left its band or raised
an alarm has disturbed the die temperature (seed Sec. 3: readings are taken
only once the die is stable), a table that missed its position has not.

Device faults are the fourth suspender; they live in the guard
(service/engine/guard.py) because they wrap every device call.
"""

from __future__ import annotations

from dataclasses import dataclass

# The band and the clear time are the campaign spec's defaults (written once there).
from calibration.campaign_spec import DEFAULT_BAND_C, DEFAULT_CLEAR_S
from drivers.protocols import ChamberStatus, TurntableStatus


@dataclass(frozen=True)
class Suspender:
    """One condition's policy."""

    name: str
    restart_soak: bool
    clear_s: float = DEFAULT_CLEAR_S
    limit_s: float = 1800.0  # real (wall) time suspended before the campaign fails


def chamber_alarm(status: ChamberStatus) -> str | None:
    """The controller's own alarm bits (deviation high/low, sensor break)."""
    if status.alarms:
        return f"chamber alarm: {', '.join(status.alarms)} (PV {status.process_c:.2f} °C)"
    return None


def chamber_out_of_band(status: ChamberStatus, setpoint_c: float, band_c: float) -> str | None:
    """Air temperature (PV) farther than ``band_c`` from the setpoint once the step is soaked."""
    dev_c = status.process_c - setpoint_c
    if abs(dev_c) > band_c:
        return (f"chamber out of band: PV {status.process_c:.2f} °C is {dev_c:+.2f} °C from "
                f"the setpoint {setpoint_c:.2f} °C (band ±{band_c:.2f} °C)")
    return None


def table_not_in_position(status: TurntableStatus, target_deg: tuple[float, ...],
                          waited_s: float) -> str:
    return (f"turntable not in position {tuple(round(a, 3) for a in target_deg)} after "
            f"{waited_s:.0f} s (at {tuple(round(a, 3) for a in status.angles_deg)}, "
            f"faults {list(status.faults)})")


@dataclass
class Suspenders:
    """The set the engine installs, with their policies (limits from the spec)."""

    band_c: float = DEFAULT_BAND_C
    limit_s: float = 1800.0
    clear_s: float = DEFAULT_CLEAR_S

    @property
    def alarm(self) -> Suspender:
        return Suspender("chamber_alarm", restart_soak=True, clear_s=self.clear_s,
                         limit_s=self.limit_s)

    @property
    def band(self) -> Suspender:
        return Suspender("chamber_band", restart_soak=True, clear_s=self.clear_s,
                         limit_s=self.limit_s)

    @property
    def table(self) -> Suspender:
        return Suspender("turntable_position", restart_soak=False, clear_s=0.0,
                         limit_s=self.limit_s)

    def check_chamber(self, status: ChamberStatus, setpoint_c: float | None
                      ) -> tuple[Suspender, str] | None:
        """The first tripped chamber suspender; ``setpoint_c`` None: band not armed (ramp)."""
        why = chamber_alarm(status)
        if why:
            return self.alarm, why
        if setpoint_c is not None:
            why = chamber_out_of_band(status, setpoint_c, self.band_c)
            if why:
                return self.band, why
        return None
