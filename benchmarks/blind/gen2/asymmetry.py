"""A scale asymmetry (``k̄·a + Δk·|a|``, effects.md) on the second generator: what is named.

    python -m benchmarks.blind.gen2.asymmetry [--sizes 20,60,200] [--seeds 3]

The second generator's own ``scale_nonlinearity`` draws a² and a³ only; this adds
``w_i·size·|a_i|`` (ppm, w the case's per-axis pattern) to its output on one-way staircases
of the oblique 36- and the 24-position schedules (sensor_c, 20-min soaks, 100 samples per
capture, 60 µg sensor noise, regular order), and prints each case's findings. Noise pools
are synthetic (white sensor noise, an AR(1) bench vibration), as in
``tests/discrepancy/test_gen2_power.py``, so no real recordings are needed (issue 22).
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.signal import lfilter

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose
from calibration.recording import Recording


def synthetic_pools() -> NoisePools:
    rng = np.random.default_rng(0)
    slow = lfilter([np.sqrt(1 - 0.9**2)], [1.0, -0.9], rng.standard_normal((20000, 3)), axis=0)
    return NoisePools(rng.standard_normal((20000, 3)), slow / slow.std(0),
                      rng.standard_normal(400))


def with_asymmetry(plain):
    """``effects.output_offset_g`` plus the key ``asym``: ``|a_i| × w_i × m`` ppm."""
    def offset(eid, m, pat, s):
        if eid != "asym":
            return plain(eid, m, pat, s)
        return np.abs(s["force_g"]) * np.asarray(pat["axes"]) * m * 1e-6
    return offset


def record(seed: int, schedule: str, size_ppm: float, pools: NoisePools) -> Recording:
    rng = np.random.default_rng(700 + seed)
    pr = protocol.draw_protocol(rng, kind="oneway", schedule=schedule, columns=("sensor_c",),
                                soak_min=20.0)
    pr = protocol.Protocol2(**{**pr.__dict__, "n_samples": 100, "sensor_noise_g": 60e-6,
                               "irregular": False})
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(pr.setpoints_c), 10)
    return Recording.from_columns(sim.record(pr, sensor, pools, "asym", size_ppm, pat, seed))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="20,60,200")
    ap.add_argument("--seeds", type=int, default=3)
    a = ap.parse_args(argv)
    plain = fx.output_offset_g
    fx.output_offset_g = with_asymmetry(plain)
    pools = synthetic_pools()
    counts: dict[str, int] = {}
    print("| schedule | size ppm | seed | findings |\n|---|---|---|---|")
    try:
        for schedule in ("oblique36", "dense24"):
            for size in (float(x) for x in a.sizes.split(",")):
                for seed in range(a.seeds):
                    d = diagnose(record(seed, schedule, size, pools), seed=0, n_null=100)
                    names = [f.effect for f in d.findings]
                    top = names[0] if names else "–"
                    counts[top] = counts.get(top, 0) + 1
                    print(f"| {schedule} | {size:g} | {seed} | {', '.join(names) or '–'} |")
    finally:
        fx.output_offset_g = plain
    print("\ntop finding: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
