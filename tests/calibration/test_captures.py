"""The one reader of raw rows: capture means with their sd and n."""

from __future__ import annotations

import json
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


def test_rows_taken_while_turning_are_left_out_and_said() -> None:
    rec, _ = warmup_log(seconds=100, rate_hz=50, seed=2, segments=[(52.5, (1, 0, 0))])
    caps = capture_means(rec)
    turning = np.abs(rec.t_s - 52.5) < 0.45  # the 1-s window reaches the turn
    assert np.all(caps.row_capture[turning] == -1)
    assert np.all(caps.row_capture[np.abs(rec.t_s - 52.5) > 1.0] >= 0)
    assert any("left out: the sensor was moving" in note for note in caps.notes)
    # no capture mixes the two orientations: each mean is one of them
    up = caps.recording.raw_g / np.linalg.norm(caps.recording.raw_g, axis=1)[:, None]
    assert np.all(np.max(np.abs(up), axis=1) > 0.999)
    assert {int(np.argmax(np.abs(u))) for u in up} == {0, 2}


def _hand_turned(seconds_per_face: float = 4.0, sweep_s: float = 1.5, rate_hz: float = 100.0,
                 seed: int = 0) -> Recording:
    """Raw rows of a sensor turned by hand through 12 orientations, the turns sweeping
    gravity across the axes over ``sweep_s``; bias 5 / -3 / 8 mg, scale 1.01 / 0.99 / 1."""
    rng = np.random.default_rng(seed)
    ups = [(1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1), (-1, 1, 1), (-1, 1, -1),
           (-1, -1, 1), (-1, -1, -1), (1, 0, 0), (0, 1, 0), (0, 0, 1), (0, -1, 0)]
    ups = [np.asarray(u, float) / np.linalg.norm(u) for u in ups]
    pieces = []
    for k, u in enumerate(ups):
        pieces.append(np.tile(u, (int(seconds_per_face * rate_hz), 1)))
        if k + 1 < len(ups):  # the hand sweeps to the next face
            f = np.linspace(0, 1, int(sweep_s * rate_hz))[:, None]
            path = (1 - f) * u + f * ups[k + 1]
            pieces.append(path / np.linalg.norm(path, axis=1)[:, None])
    true_g = np.vstack(pieces)
    raw = true_g * np.array([1.01, 0.99, 1.0]) + np.array([5e-3, -3e-3, 8e-3])
    raw = raw + rng.normal(0.0, 1e-3, raw.shape)
    t = np.arange(raw.shape[0]) / rate_hz
    return Recording.from_columns({"t_s": t, "chamber_c": np.full(t.size, np.nan),
                                   "ax": raw[:, 0], "ay": raw[:, 1], "az": raw[:, 2]},
                                  path="turned.csv")


def test_raw_rows_of_a_hand_turned_sensor_become_still_captures_only() -> None:
    caps = capture_means(_hand_turned())
    norm = np.linalg.norm(caps.recording.raw_g, axis=1)
    # every capture is one placement: |mean| is the biased, scaled 1 g, none a mid-turn
    # direction averaged down to 0.7 g (5-s blocks straddling the turns did that)
    assert np.all(np.abs(norm - 1.0) < 0.03)
    assert any("left out: the sensor was moving" in note for note in caps.notes)


def test_calibrate_fits_a_hand_turned_sensors_raw_rows(tmp_path: Path, capsys) -> None:
    src = tmp_path / "turned.csv"
    write_recording(src, _hand_turned(seed=1))

    class A:
        pass

    a = A()
    a.recording, a.output = str(src), str(tmp_path / "m.json")
    a.json = True
    assert cli.run_calibrate(a) == 0
    from calibration.model_file import load_model

    doc = json.loads(capsys.readouterr().out)
    assert doc["mode"] == "norm"
    # the fitted biases and scales (Eq. 1: A undoes the gain) are the simulated ones
    m = load_model(a.output)
    vec = m.params_vector_at(m.t_centre_c, extrapolate=True)
    np.testing.assert_allclose(vec[:3], [5e-3, -3e-3, 8e-3], atol=1e-3)
    np.testing.assert_allclose(vec[3:6], 1.0 / np.array([1.01, 0.99, 1.0]), atol=2e-3)


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


def _args(recording: Path, output: Path) -> object:
    class A:
        pass

    a = A()
    a.recording, a.output, a.json, a.model = str(recording), str(output), True, None
    a.n_null, a.against, a.write_twin, a.report_dir, a.seed = None, None, None, None, None
    return a


def test_block_means_averaged_across_a_turn_are_left_out_and_said(tmp_path: Path,
                                                                   capsys) -> None:
    # 1-s block means of the hand-turned log (`soakcal import --block-s 1`): the blocks
    # across the turns scatter by tenths of a g and read directions the sensor never
    # rested in. They are left out (a still accelerometer stays under 10 mg), the note
    # says how many, and the still blocks give the simulated biases.
    rec = _hand_turned(seed=2)
    block = np.floor(rec.t_s).astype(int)
    from calibration.captures import group_means

    src = tmp_path / "blocks.csv"
    blocks = Recording.from_columns(group_means(rec, block))
    write_recording(src, blocks)
    turning = int(np.sum(np.max([blocks.columns[c] for c in ("sd_x", "sd_y", "sd_z")],
                                axis=0) > 10e-3))
    assert turning >= 11  # every one of the 11 sweeps spoils at least one block
    a = _args(src, tmp_path / "m.json")
    assert cli.run_calibrate(a) == 0
    doc = json.loads(capsys.readouterr().out)
    note = next(n for n in doc["notes"] if "left out" in n)
    assert note.startswith(f"{turning} of {len(blocks)} row(s) left out: their sample "
                           f"scatter (up to ")
    assert "the sensor moved or vibrated while they were averaged" in note
    from calibration.model_file import load_model

    vec = load_model(a.output).params_vector_at(25.0, extrapolate=True)
    np.testing.assert_allclose(vec[:3], [5e-3, -3e-3, 8e-3], atol=1e-3)


def test_a_flight_as_block_means_is_refused_and_not_diagnosed(tmp_path: Path,
                                                              capsys) -> None:
    # A newer ArduPilot flight (IMU with T) imported as 5-s blocks: every block is the
    # mean of a vibrating, swaying vehicle. calibrate refuses "no still reading" (not a
    # warm-up fitted to the attitude's wander); diagnose says "cannot judge", same reason.
    import argparse

    from calibration.importers_cli import run_import
    from tests.calibration.log_writers import flight_samples, write_dataflash

    t_us, acc = flight_samples(seconds=120.0, vibration_g=0.04)
    temp = np.linspace(30.0, 45.0, t_us.size)
    log = write_dataflash(tmp_path / "flight.bin", t_us, acc, temp)
    src = tmp_path / "blocks.csv"
    assert run_import(argparse.Namespace(
        format="dataflash", raw=str(log), output=str(src), raw_samples=False,
        min_static_s=None, threshold=None, window_s=None, trim_s=None, block_s=5.0)) == 0
    capsys.readouterr()
    a = _args(src, tmp_path / "m.json")
    assert cli.run_calibrate(a) == 2
    refusal = capsys.readouterr().err.strip()
    assert "no still reading" in refusal and "held still" in refusal
    assert not Path(a.output).exists()
    assert cli.run_diagnose(a) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["verdict"] == "cannot judge" and doc["mismatch"] is None
    assert doc["reason"] in refusal


def _noisy_still_warmup() -> tuple[Recording, object]:
    # A noisy part held still while it warms (as the real inclinometer log: 500 Hz, 7-18 mg
    # of white noise per sample, -18.7 -> -13.3 °C): above the 10 mg a still part's samples
    # usually stay under, yet its 0.1-s means scatter by 0.7 mg.
    return warmup_log(seconds=120, rate_hz=500, noise_g=15e-3, quantum_c=None, seed=4)


def _bias_change_mg(model_path: str, truth: object, lo: float, hi: float) -> tuple[float, float]:
    from calibration.model_file import load_model

    model = load_model(model_path)
    fitted = (model.params_vector_at(hi, extrapolate=True)[2]
              - model.params_vector_at(lo, extrapolate=True)[2])
    true = truth.bias_g(np.array([hi]))[0, 2] - truth.bias_g(np.array([lo]))[0, 2]
    return 1e3 * fitted, 1e3 * true


def test_a_noisy_part_held_still_is_still_as_raw_rows_and_as_block_means(
        tmp_path: Path, capsys) -> None:
    rec, truth = _noisy_still_warmup()
    lo, hi = float(rec.temperature_c().min()), float(rec.temperature_c().max())
    raw = tmp_path / "raw.csv"
    write_recording(raw, rec)
    a = _args(raw, tmp_path / "raw.json")
    assert cli.run_calibrate(a) == 0, capsys.readouterr().err
    doc = json.loads(capsys.readouterr().out)
    assert not any("left out" in n for n in doc["notes"]), doc["notes"]
    fitted, true = _bias_change_mg(a.output, truth, lo, hi)
    assert abs(fitted - true) < 0.5, (fitted, true)
    # the same log as 1-s block means (`soakcal import --block-s 1`): every block's sample
    # sd is 15 mg, but their means agree with their neighbours': kept, and said
    from calibration.captures import group_means

    blocks = Recording.from_columns(group_means(rec, np.floor(rec.t_s).astype(int)))
    src = tmp_path / "blocks.csv"
    write_recording(src, blocks)
    a = _args(src, tmp_path / "blocks.json")
    assert cli.run_calibrate(a) == 0, capsys.readouterr().err
    doc = json.loads(capsys.readouterr().out)
    note = next(n for n in doc["notes"] if "kept as still" in n)
    assert note.startswith(f"{len(blocks)} row(s) scatter sample by sample above the 10 mg")
    fitted, true = _bias_change_mg(a.output, truth, lo, hi)
    assert abs(fitted - true) < 0.5, (fitted, true)


def test_a_flight_as_raw_rows_with_a_temperature_is_refused_not_a_traceback(
        tmp_path: Path, capsys) -> None:
    # Every raw row of a flight is left out as moving: calibrate refuses "no still
    # reading" (an empty set of captures with a sensor_c column ended in a KeyError).
    import argparse

    from calibration.importers_cli import run_import
    from tests.calibration.log_writers import flight_samples, write_dataflash

    t_us, acc = flight_samples(seconds=60.0, vibration_g=0.04)
    log = write_dataflash(tmp_path / "flight.bin", t_us, acc, np.linspace(30.0, 40.0, t_us.size))
    src = tmp_path / "rows.csv"
    assert run_import(argparse.Namespace(
        format="dataflash", raw=str(log), output=str(src), raw_samples=False,
        min_static_s=None, threshold=None, window_s=None, trim_s=None)) == 0
    capsys.readouterr()
    a = _args(src, tmp_path / "m.json")
    assert cli.run_calibrate(a) == 2
    assert capsys.readouterr().err.startswith("error: ")
    assert not Path(a.output).exists()
