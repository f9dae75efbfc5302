"""Campaign protocols of the blind benchmark: what the twin's rig does, identical for every
case of a protocol (so no column betrays the concealed effect)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.schedules import get_schedule
from simulators.campaign_sim import RigPhysics, compressor_vibration

UP = tuple(float(t) for t in range(-40, 61, 10))
UP_DOWN = UP + UP[-2::-1]


@dataclass(frozen=True)
class Protocol:
    name: str
    setpoints_c: tuple[float, ...]
    schedule: str
    soak_min: float
    columns: tuple[str, ...]  # temperature columns recorded
    die_tau_s: float  # fixture lag of the rig when no lag is concealed
    power_cycle_at_step: int | None = None  # a second power session from this step on
    vib_cold_sd_g: float = 0.0  # compressor vibration below 0 °C (rms g)
    description: str = ""

    def refs(self) -> np.ndarray:
        return get_schedule(self.schedule)

    def sessions(self) -> list[int] | None:
        if self.power_cycle_at_step is None:
            return None
        return [int(k >= self.power_cycle_at_step) for k in range(len(self.setpoints_c))]

    def physics(self) -> RigPhysics:
        vib = compressor_vibration(self.setpoints_c, self.vib_cold_sd_g)
        return RigPhysics(die_tau_s=self.die_tau_s, vib_sd_g_by_step=vib)


PROTOCOLS: dict[str, Protocol] = {p.name: p for p in (
    Protocol("oneway", UP, "table1", 60.0, ("chamber_c", "sensor_c"), 600.0,
             vib_cold_sd_g=0.5e-3,
             description="one-way staircase −40→60 °C, 60 min soak, Table 1, chamber+sensor T, "
                         "compressor vibration 0.5 mg rms below 0 °C"),
    Protocol("updown", UP_DOWN, "table1", 60.0, ("chamber_c", "sensor_c"), 600.0,
             power_cycle_at_step=16, vib_cold_sd_g=0.5e-3,
             description="−40→60→−40 °C, 60 min soak, Table 1, chamber+sensor T, power cycle "
                         "before step 16, compressor vibration below 0 °C"),
    Protocol("short_soak", UP, "table1", 20.0, ("chamber_c",), 30.0,
             description="one-way −40→60 °C, 20 min soak, Table 1, chamber T only"),
    Protocol("updown_short", UP_DOWN, "table1", 20.0, ("chamber_c",), 30.0,
             description="−40→60→−40 °C, 20 min soak, Table 1, chamber T only"),
    Protocol("oblique", UP, "table1+cube14", 60.0, ("chamber_c", "sensor_c"), 600.0,
             description="one-way −40→60 °C, 60 min soak, Table 1 + cube14 (38 positions)"),
)}
