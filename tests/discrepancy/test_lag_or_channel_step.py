"""A die lag left after long soaks against a step of the temperature channel (issue 22).

On a chamber_c-only up-down campaign whose die lags the air by τ = 15 min and soaks 6 τ, the
lag left at the captures is nearly constant through each plateau and flips sign with the
direction of the last step: a step of the channel at the turn has that shape. The diagnosis
must not name ``temperature_sensor`` there as if the lag were not a candidate. Recordings
from the second blind generator (unseen protocol family) with synthetic white noise pools.
"""

import numpy as np
import pytest

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import diagnose
from calibration.recording import Recording


def _slow_die_updown(noise_seed: int) -> Recording:
    """An up-down staircase −30…60 °C, 36 oblique positions in random order, 100 samples,
    74 µg of sensor noise and 0.5 mg of bench vibration on the cold plateaus; chamber_c only,
    the die τ = 900 s soaked 90 min (a null of the unseen family that was named a channel
    step; the sensor of that case, the noise white here)."""
    up = tuple(float(t) for t in range(-30, 61, 10))
    sp = up + up[-2::-1]
    pr = protocol.Protocol2(
        name="slowdie/oblique36/updown/chamber_c/90min", setpoints_c=sp, soak_min=90.0,
        schedule="oblique36", columns=("chamber_c",), die_tau_s=900.0, n_samples=100,
        vib_sd_g=tuple(0.53e-3 if t < 5.0 else 0.0 for t in sp), irregular=True,
        power_cycle_at=9, sensor_noise_g=73.8e-6)
    rng = np.random.default_rng(200359)
    sensor = draw_sensor(rng)
    pat = fx.pattern(rng, len(sp), 10)
    r2 = np.random.default_rng(100 + noise_seed)
    pools = NoisePools(r2.standard_normal((5000, 3)), r2.standard_normal((5000, 3)),
                       r2.standard_normal(400))
    return Recording.from_columns(sim.record(pr, sensor, pools, None, 0.0, pat,
                                             200359 + noise_seed))


# Before the channel step declared the lag its confuser, noise seeds 1 and 3 were named
# temperature_sensor (seed 0 thermal_lag): the test fails there.
@pytest.mark.parametrize("noise_seed", [0, 1, 3])
def test_a_soaked_die_lag_is_not_named_a_channel_step(noise_seed):
    d = diagnose(_slow_die_updown(noise_seed), seed=0, n_null=400)
    assert d.mismatch  # the lag is there: 0.02–0.04 °C left at the captures
    top = d.findings[0]
    assert top.effect != "temperature_sensor"
    if top.effect == "not_identifiable":
        assert {"thermal_lag", "temperature_sensor"} <= set(top.where["candidates"])
    else:
        assert top.effect == "thermal_lag"
