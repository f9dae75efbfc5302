"""benchmarks/blind/gen2/scene_replay.py: the scatter the second generator draws.

``simulate.reading_sigma_g`` is the scatter ``detect.py`` sizes every effect by and
``scene_replay --first-stage`` compares the noise scale ``diagnose`` whitens by with
(docs/benchmarks.md, "Wrong names at 1× on min12 schedules"). Its re-seating part must be
what ``simulate.record`` draws: three angle components of sd ``placement_rad`` each, crossed
with the force, so ρ²(1 − f_a²) on axis a (it counted it twice: √2 too large across the
force on a hand-placed fixture).
"""

from dataclasses import replace

import numpy as np

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.protocol import draw_protocol
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor


def test_the_reseating_scatter_is_what_record_draws():
    rng = np.random.default_rng(3)
    quiet = np.zeros((5000, 3))
    pools = NoisePools(sensor=quiet, vibration=quiet,
                       placement=rng.standard_normal(20000))
    proto = draw_protocol(rng, schedule="dense24")
    proto = replace(proto, placement_rad=2e-3, vib_sd_g=(0.0,) * len(proto.setpoints_c),
                    sensor_noise_g=0.0, n_samples=10, irregular=False)
    pat = fx.pattern(rng, len(proto.setpoints_c), 10_000)
    sensor = draw_sensor(rng)
    seed = 11
    sc = sim.scene(proto, None, 0.0, pat, seed)
    clean = sim.noise_free_output(sensor, sc, None, 0.0, pat)
    # Many draws of the same scene: the record seed moves the noise, the scene stays (its
    # seed only orders an irregular protocol's visits; this one is visited in order).
    draws = []
    for k in range(120):
        cols = sim.record(proto, sensor, pools, None, 0.0, pat, seed + 7919 * (k + 1))
        draws.append(np.column_stack([cols[c] for c in ("ax", "ay", "az")]) - clean)
    sd = np.std(np.stack(draws), axis=0)  # (N, 3) over the draws
    want = sim.reading_sigma_g(proto, pools, sc)
    across = (1.0 - sc.ref_g**2) > 0.5
    assert 0.9 < np.median(sd[across] / want[across]) < 1.1
