"""The one reader of raw rows: capture means with their sd and n."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration import cli
from calibration.captures import capture_means, capture_temperature_c, is_raw_samples
from calibration.recording import Recording, write_recording
from simulators.warmup_log import warmup_log


def test_raw_samples_become_five_second_capture_means_with_sd_and_n() -> None:
    rec, _ = warmup_log(seconds=60, rate_hz=100, noise_g=1e-3, seed=1)
    caps = capture_means(rec)
    assert caps.is_raw and caps.raw_rows == 6000
    means = caps.recording
    assert len(means) == 12
    np.testing.assert_array_equal(means.columns["n"], 500)
    # each capture's sd is the sample noise; its mean temperature de-quantises the channel
    np.testing.assert_allclose(means.columns["sd_z"], 1e-3, rtol=0.1)
    assert len(np.unique(means.temperature_c())) == 12
    np.testing.assert_array_equal(np.bincount(caps.row_capture), 500)


def test_averaged_readings_pass_through_unchanged() -> None:
    n = 24
    rec = Recording.from_columns({
        "t_s": np.arange(n) * 10.0, "chamber_c": np.full(n, 25.0), "ax": np.zeros(n),
        "ay": np.zeros(n), "az": np.ones(n), "n": np.full(n, 100.0),
        "sd_x": np.full(n, 1e-3), "sd_y": np.full(n, 1e-3), "sd_z": np.full(n, 1e-3)})
    assert not is_raw_samples(rec)
    assert capture_means(rec).recording is rec


def test_a_capture_taken_while_turning_is_left_out_and_said() -> None:
    rec, _ = warmup_log(seconds=100, rate_hz=50, seed=2, segments=[(52.5, (1, 0, 0))])
    caps = capture_means(rec)
    assert len(caps.recording) == 19  # 20 blocks, the one with the turn left out
    assert any("1 capture(s) left out" in note for note in caps.notes)
    assert np.all(caps.row_capture[(rec.t_s >= 50) & (rec.t_s < 55)] == -1)


def test_compensate_reads_raw_rows_at_their_captures_temperature(tmp_path: Path,
                                                                  capsys) -> None:
    rec, _ = warmup_log(seconds=120, rate_hz=50, seed=6)
    src, model, out = tmp_path / "w.csv", tmp_path / "m.json", tmp_path / "c.csv"
    write_recording(src, rec)

    class A:
        pass

    a = A()
    a.recording, a.output, a.model = str(src), str(model), str(model)
    assert cli.run_calibrate(a) == 0
    a.output = str(out)
    # every row, the hottest included, is inside the model's valid range: no --extrapolate
    assert cli.run_compensate(a) == 0
    assert "each row at its capture's mean temperature" in capsys.readouterr().out
    temp = capture_temperature_c(rec, capture_means(rec))
    assert np.max(np.abs(np.diff(temp))) < 0.01  # no 0.06 °C quantisation steps left
    cols = np.genfromtxt(out, delimiter=",", names=True)
    cz = cols["cz"]
    # the drift (1.1 mg on z over this log) is gone: first and last 10 s agree within noise
    assert abs(cz[:500].mean() - cz[-500:].mean()) < 1e-4
    assert abs(rec.raw_g[:500, 2].mean() - rec.raw_g[-500:, 2].mean()) > 5e-4
    # and with each row's own (quantised) reading, still no --extrapolate needed
    a.raw_temperature = True
    assert cli.run_compensate(a) == 0


def test_raw_rows_and_their_five_second_means_give_the_same_model(tmp_path: Path) -> None:
    # Acceptance must not depend on the noise level of the rows: the raw log and the
    # same data as 5-s means are one warm-up with one bias change.
    from calibration.model_file import load_model

    rec, _ = warmup_log(seconds=150, rate_hz=50, seed=10)
    raw, means = tmp_path / "raw.csv", tmp_path / "means.csv"
    write_recording(raw, rec)
    write_recording(means, capture_means(rec).recording)
    models = []
    for src in (raw, means):
        class A:
            pass

        a = A()
        a.recording, a.output = str(src), str(tmp_path / f"{src.stem}.json")
        assert cli.run_calibrate(a) == 0
        models.append(load_model(a.output))
    assert [m.mode for m in models] == ["warmup", "warmup"]
    lo, hi = models[1].valid_c  # the means' span, inside the raw rows' span
    changes = [m.params_vector_at(hi)[:3] - m.params_vector_at(lo)[:3] for m in models]
    np.testing.assert_allclose(changes[0], changes[1], atol=1e-6)
    # Each capture mean is compensated at its own temperature, all inside the span (a
    # causal filter's line overshoots a warm-up's curve and was refused at its end).
    a.model, a.recording, a.output = a.output, str(means), str(tmp_path / "c.csv")
    assert cli.run_compensate(a) == 0
    cz = np.genfromtxt(a.output, delimiter=",", names=True)["cz"]
    assert np.ptp(cz) < 0.5 * np.ptp(capture_means(rec).recording.raw_g[:, 2])


def test_labels_are_kept_whole_not_averaged() -> None:
    rec, _ = warmup_log(seconds=20, rate_hz=50, seed=3)
    cols = dict(rec.columns)
    cols["position"] = np.zeros(len(rec))
    cols["visit"] = np.arange(len(rec), dtype=float)  # a per-sample index
    means = capture_means(Recording.from_columns(cols)).recording
    np.testing.assert_array_equal(means.columns["visit"], [0, 250, 500, 750])
    np.testing.assert_array_equal(means.columns["position"], 0)
