"""``diagnose --against`` across protocols (issue 22): a model calibrated on an up-down run
and the same sensor re-measured on a one-way staircase of other positions must agree within
their joint uncertainty; a re-mount about z is a shift of ψ (``mz``), not of a bias.

Recordings from the second blind generator (benchmarks/blind/gen2) with synthetic white
noise pools (the benchmark reads real ones from a directory outside the repository).
"""

import numpy as np
import pytest

from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import NoisePools
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy.against import diagnose_against
from calibration.discrepancy.twin_file import Twin
from calibration.recording import Recording
from calibration.thermal import fit_campaign


@pytest.fixture(scope="module")
def pair():
    rng = np.random.default_rng(7)
    pools = NoisePools(rng.standard_normal((20000, 3)), rng.standard_normal((20000, 3)),
                       rng.standard_normal(400))
    sensor = draw_sensor(rng)
    cal = protocol.draw_protocol(rng, kind="updown", schedule="dense24", columns=("sensor_c",),
                                 soak_min=20.0)
    again = protocol.draw_protocol(rng, kind="staircase_down", schedule="oblique36",
                                   columns=("sensor_c",), soak_min=20.0)
    pat = fx.pattern(rng, 3, 10)
    given = Recording.from_columns(sim.record(cal, sensor, pools, None, 0.0, pat, 1))
    model = Twin(fit_campaign(given).model)

    def remeasure(s):
        return Recording.from_columns(sim.record(again, s, pools, None, 0.0, pat, 2))
    return model, sensor, remeasure


def test_an_unchanged_sensor_on_another_protocol_has_no_parameter_shift(pair):
    model, sensor, remeasure = pair
    d = diagnose_against(remeasure(sensor), model, n_null=50, refit=False)
    assert "parameter_shift" not in [f["effect"] for f in d.findings]
    assert d.mismatch is False


def test_a_remount_about_z_is_named_psi_not_a_bias(pair):
    model, sensor, remeasure = pair
    d = diagnose_against(remeasure(sensor.rotated_z(2e-3)), model, n_null=50, refit=False)
    (f,) = [f for f in d.findings if f["effect"] == "parameter_shift"]
    names = list(f["parameters"])
    assert any(n.startswith("d_mz") for n in names), names
    assert not any(n.startswith(("d_bx", "d_by", "d_bz")) for n in names), names
    mz = next(v for n, v in f["parameters"].items() if n.startswith("d_mz"))
    assert abs(mz) == pytest.approx(2000.0, rel=0.1)  # µrad
