"""benchmarks/blind/gen3 (issue 22): the third blind generator writes a recording the
project reads, whose per-capture scatter is what was drawn, the same for the same seed."""

import dataclasses

import numpy as np

from benchmarks.blind.gen3.case import draw_case, simulate
from benchmarks.blind.gen3.noise import NoiseSpec
from benchmarks.blind.gen3.protocol import Protocol
from benchmarks.blind.gen3.schedules import faces
from benchmarks.blind.gen3.writer import write_csv
from calibration.recording import read_recording


def _small_case(seed: int, n: int = 200):
    """A drawn case cut to 4 plateaus × 6 faces × 2 visits on a table, white noise only."""
    case = draw_case(seed)
    protocol = Protocol(setpoints_c=(-40.0, -7.0, 27.0, 60.0), order="up",
                        schedule_name="faces", directions=faces(), visits=2, shuffled=True,
                        fixture="table", place_max_rad=0.0, move_s=20.0)
    noise = NoiseSpec(odr_hz=125.0, n=n, density_g=np.array([20e-6, 25e-6, 30e-6]),
                      nu=None, vibration=None, raw_lsb_g=None)
    return dataclasses.replace(case, protocol=protocol, noise=noise)


def test_the_recording_reads_back_with_every_capture(tmp_path):
    case = _small_case(5)
    rows = simulate(case)
    write_csv(rows, tmp_path / "null.csv")
    rec = read_recording(str(tmp_path / "null.csv"))
    assert len(rec) == 4 * 6 * 2
    assert rec.has_reference and rec.temperature_source == "sensor_c"
    np.testing.assert_allclose(rec.raw_g[:, 2], [r["az"] for r in rows], atol=1e-9)
    assert np.all(np.diff(rec.t_s) > 0)


def test_the_scatter_is_the_drawn_noise_and_the_means_scatter_by_sd_over_root_n():
    case = _small_case(6, n=400)
    rows = simulate(case)
    sd = np.array([[r["sd_x"], r["sd_y"], r["sd_z"]] for r in rows])
    drawn = case.noise.sample_sigma_g
    np.testing.assert_allclose(np.sqrt(np.mean(sd**2, axis=0)) / drawn, 1.0, atol=0.02)
    err = np.array([r["err_g"] for r in rows]) / (sd / np.sqrt(400))
    assert 0.8 < np.sqrt(np.mean(err**2)) < 1.2


def test_one_seed_one_recording(tmp_path):
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        write_csv(simulate(_small_case(seed)), tmp_path / f"{name}.csv")
    text = {n: (tmp_path / f"{n}.csv").read_text() for n in "abc"}
    assert text["a"] == text["b"]
    assert text["a"] != text["c"]
