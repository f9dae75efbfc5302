"""A second-generator staircase whose plateaus the noise model whitens unevenly: the
recording the checks' level tests start from (synthetic noise pools, one seeded sensor)."""

from __future__ import annotations

import numpy as np

from benchmarks.blind.gen2 import protocol as gp
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.recording import Recording

# The vibrating plateaus' whitened variance (quiet 1; the generator: 0.7–0.8 against 0.9–1.0)
LOUD_VARIANCE = 0.25


def uneven_staircase(setpoints_c: tuple[float, ...], schedule: str, loud_from: int, *,
                     effect: str | None = None, size: float = 0.0,
                     from_step: int = 3) -> Recording:
    """A one-way staircase over ``setpoints_c`` on ``schedule`` (sensor_c, 10-min soaks,
    200 samples), the plateaus from ``loud_from`` on vibrating (5e-4 g), with ``effect``
    of ``size`` (the generator's units) concealed, its change from ``from_step``."""
    rng = np.random.default_rng(0)
    pools = NoisePools(rng.standard_normal((20000, 3)), rng.standard_normal((20000, 3)),
                       rng.standard_normal(400))
    vib = tuple(5e-4 if k >= loud_from else 0.0 for k in range(len(setpoints_c)))
    proto = gp.Protocol2(name=f"staircase_down/{schedule}/sensor_c/10min",
                         setpoints_c=setpoints_c, soak_min=10.0, schedule=schedule,
                         columns=("sensor_c",), die_tau_s=470.0, n_samples=200, vib_sd_g=vib,
                         irregular=False, power_cycle_at=None, sensor_noise_g=1e-4)
    pat = {"axes": [1.0, -0.7, -0.4], "from_step": from_step, "rows": [0, 1], "axis": 0,
           "band_lo_g": 0.3, "tilt_dir": 0.0, "crack_frac": 0.5}
    cols = sim.record(proto, draw_sensor(np.random.default_rng(3)), pools, effect, size, pat, 3)
    return Recording.from_columns(cols)


def loud_sd(pb, loud_from: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Each whitened row's noise SD: 1 on the quiet plateaus, √LOUD_VARIANCE on the
    vibrating ones."""
    return np.where(pb.ctx.steps[pb.row] >= loud_from, np.sqrt(LOUD_VARIANCE), 1.0)
