"""``soakcal export --format px4|ardupilot``: each firmware's own application formula,
written here from its source (PX4 TemperatureCompensation::calc_thermal_offsets_3D and
calibration::Accelerometer::Correct; ArduPilot AP_InertialSensor::TCal::correct_sensor),
applied to the exported parameters, against ``soakcal compensate``."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from calibration.model_file import load_model, save_model
from calibration.recording import Recording
from calibration.thermal import ThermalModel
from service.cli import main
from tests.calibration.firmware_files import ardupilot_params, px4_params

G = 9.80665
F32 = np.float32


def _model(*, scale_ppm: float = 0.0, scale_tc_ppm: float = 0.0, misalign_rad: float = 0.0,
           degree: int = 3, source: str = "sensor_c") -> ThermalModel:
    """Bias cubics in x = (T − 20)/30 over −10..50 °C (g), optional scale/misalignment."""
    coeffs = np.zeros((12, degree + 1))
    coeffs[0, :4] = [0.004, 0.0015, -0.0004, 0.0002][: degree + 1] if degree >= 3 else 0.004
    coeffs[1, :2] = [-0.003, 0.0008]
    coeffs[2, :3] = [0.010, -0.0020, 0.0009]
    coeffs[3:6, 0] = 1.0 + scale_ppm * 1e-6
    if degree >= 1:
        coeffs[5, 1] = scale_tc_ppm * 1e-6
    coeffs[9, 0] = misalign_rad
    return ThermalModel(coeffs=coeffs, t_centre_c=20.0, t_scale_c=30.0, valid_c=(-10.0, 50.0),
                        mode="reference", identifiable=np.ones(12, bool),
                        temperature_source=source)


def _readings(n: int = 200, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    raw = rng.normal(0, 1, (n, 3))
    raw /= np.linalg.norm(raw, axis=1)[:, None]
    return raw, rng.uniform(-10.0, 50.0, n)


def _compensate(tmp: Path, model: Path, raw: np.ndarray, temp: np.ndarray) -> np.ndarray:
    rec = tmp / "rec.csv"
    with rec.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t_s", "sensor_c", "ax", "ay", "az"])
        for i, (r, t) in enumerate(zip(raw, temp, strict=True)):
            w.writerow([i, repr(float(t)), *map(repr, map(float, r))])
    out = tmp / "comp.csv"
    assert main(["compensate", str(model), str(rec), "-o", str(out), "--raw-temperature"]) == 0
    with out.open() as f:
        rows = list(csv.DictReader(f))
    return np.array([[float(r["cx"]), float(r["cy"]), float(r["cz"])] for r in rows])


def _export(tmp: Path, model: ThermalModel, fmt: str, *extra: str) -> tuple[Path, str, int]:
    path = tmp / "model.json"
    save_model(path, model)
    out = tmp / f"out.{fmt}"
    code = main(["export", str(path), "--format", fmt, "-o", str(out), *extra])
    return path, out.read_text() if out.exists() else "", code


def _px4_correct(p: dict[str, float], raw_ms2: np.ndarray, temp_c: np.ndarray) -> np.ndarray:
    """PX4: offset = X0 + X1 d + X2 d² + X3 d³, d = clamp(T) − TREF; data − offset (float)."""
    out = np.empty_like(raw_ms2, dtype=F32)
    for n, (r, t) in enumerate(zip(raw_ms2, temp_c, strict=True)):
        t = F32(t)
        if t > F32(p["TC_A0_TMAX"]):
            d = F32(p["TC_A0_TMAX"]) - F32(p["TC_A0_TREF"])
        elif t < F32(p["TC_A0_TMIN"]):
            d = F32(p["TC_A0_TMIN"]) - F32(p["TC_A0_TREF"])
        else:
            d = t - F32(p["TC_A0_TREF"])
        d2, d3 = d * d, d * d * d
        for i in range(3):
            off = (F32(p[f"TC_A0_X0_{i}"]) + F32(p[f"TC_A0_X1_{i}"]) * d
                   + F32(p[f"TC_A0_X2_{i}"]) * d2 + F32(p[f"TC_A0_X3_{i}"]) * d3)
            out[n, i] = F32(r[i]) - off
    return out.astype(float)


def _ap_correct(p: dict[str, float], raw_ms2: np.ndarray, temp_c: np.ndarray,
                cal_temp_c: float) -> np.ndarray:
    """ArduPilot: v −= P(clamp(T) − 35) − P(clamp(T_cal) − 35), P = (c1 d + c2 d² + c3 d³)e-6."""
    c = [np.array([F32(p[f"INS_TCAL1_ACC{k}_{a}"]) for a in "XYZ"], F32) for k in (1, 2, 3)]

    def poly(d: F32) -> np.ndarray:
        return (c[0] + (c[1] + c[2] * d) * d) * d * F32(1e-6)

    lo, hi = F32(p["INS_TCAL1_TMIN"]), F32(p["INS_TCAL1_TMAX"])
    cal = F32(min(max(cal_temp_c, lo), hi))
    # All samples at once, each operation in float32 as the firmware's per-sample code
    # (elementwise float32 arithmetic rounds as the scalar one does, in the same order).
    tc = np.clip(np.asarray(temp_c).astype(F32), lo, hi)[:, None]
    assert len(tc) == len(raw_ms2)
    out = np.asarray(raw_ms2).astype(F32) - poly(tc - F32(35.0)) + poly(cal - F32(35.0))
    return out.astype(float)



def _calibrated(tmp_path: Path, rec: Recording) -> tuple[Path, Path]:
    """``rec`` written as a recording and calibrated by the CLI's own calibrate: (the
    recording's path, the model file's path)."""
    from types import SimpleNamespace

    from calibration import cli
    from calibration.recording import write_recording

    src, path = tmp_path / "w.csv", tmp_path / "model.json"
    write_recording(src, rec.columns)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(path),
                                             json=True)) == 0
    return src, path

def test_px4_firmware_formula_reproduces_compensate(tmp_path, capsys):
    model = _model()
    path, text, code = _export(tmp_path, model, "px4", "--device-id", "1310988")
    assert code == 0
    p = px4_params(text)
    assert p["TC_A_ENABLE"] == 1 and p["TC_A0_ID"] == 1310988
    assert (p["TC_A0_TMIN"], p["TC_A0_TMAX"], p["TC_A0_TREF"]) == (-10.0, 50.0, 20.0)
    raw, temp = _readings()
    fw_g = _px4_correct(p, raw * G, temp) / G
    ours = _compensate(tmp_path, path, raw, temp)
    assert np.max(np.abs(fw_g - ours)) < 2e-6  # float32 firmware vs double: within 2 µg
    assert "cannot express" not in capsys.readouterr().err  # bias-only: nothing left out


def test_ardupilot_firmware_formula_reproduces_compensate(tmp_path, capsys):
    model = _model()
    path, text, code = _export(tmp_path, model, "ardupilot")
    assert code == 0
    p = ardupilot_params(text)
    assert (p["INS_TCAL1_ENABLE"], p["INS_TCAL1_TMIN"], p["INS_TCAL1_TMAX"]) == (1, -10, 50)
    raw, temp = _readings()
    cal_temp = 27.0  # INS_ACC1_CALTEMP of the ordinary calibration...
    accoffs = model.params_vector_at(cal_temp)[:3] * G  # ...which measured INS_ACCOFFS there
    fw_g = (_ap_correct(p, raw * G, temp, cal_temp) - accoffs) / G
    ours = _compensate(tmp_path, path, raw, temp)
    assert np.max(np.abs(fw_g - ours)) < 2e-6
    err = capsys.readouterr().err
    assert "the constant offset is not in INS_TCAL" in err


def test_what_the_firmware_cannot_express_is_said_and_bounded(tmp_path, capsys):
    model = _model(scale_ppm=800.0, scale_tc_ppm=300.0, misalign_rad=0.002)
    path, text, code = _export(tmp_path, model, "px4")
    assert code == 0
    err = capsys.readouterr().err
    for words in ("scale factors", "scale change with temperature",
                  "misalignment (up to 2.000 mrad)", "TC_A0_ID is 0"):
        assert words in err and words in text
    bound_mg = float(err.split("costs up to ")[1].split(" mg")[0])
    raw, temp = _readings()
    fw_g = _px4_correct(px4_params(text), raw * G, temp) / G
    ours = _compensate(tmp_path, path, raw, temp)
    worst_mg = np.max(np.linalg.norm(fw_g - ours, axis=1)) * 1e3
    # the stated bound holds and is not vacuous (the readings reach 60 % of it at least)
    assert 0.6 * bound_mg < worst_mg <= bound_mg * 1.001


def test_px4_warmup_model_leaves_the_constant_to_the_ordinary_calibration() -> None:
    """A warm-up identifies the bias change only: X0 = 0, and the firmware plus the
    CAL_ACC offset an ordinary calibration measures at TREF reproduce compensate."""
    from calibration.export_firmware import export_px4

    model = _model()
    model.mode = "warmup"
    fw = export_px4(model, device_id=1)
    p = px4_params(fw.text)
    assert [p[f"TC_A0_X0_{i}"] for i in range(3)] == [0.0, 0.0, 0.0]
    assert "X0 = 0: this model does not identify the constant offset" in fw.text
    raw, temp = _readings()
    cal_off = model.params_vector_at(p["TC_A0_TREF"])[:3] * G  # CAL_ACC0_OFF measured at TREF
    fw_g = (_px4_correct(p, raw * G, temp) - cal_off) / G
    np.testing.assert_allclose(fw_g, model.compensate(raw, temp), atol=2e-6)


def test_a_bias_not_fitted_is_said_as_what_the_file_does_on_that_axis() -> None:
    """A warm-up that saw no change of x's bias beyond the noise holds bx: the file's x
    offset is then flat in temperature, and the line says so with the model's reason."""
    from calibration import sfem
    from calibration.export_firmware import export_px4

    model = _model()
    model.mode = "warmup"
    model.coeffs[sfem.BIAS][0, :] = 0.0
    ident = list(model.identifiable)
    ident[0] = False
    model.identifiable = ident
    model.held = {"bx": "held at 0: no change with temperature above the noise on this axis"}
    fw = export_px4(model, device_id=1)
    line = next(x for x in fw.limitations if x.startswith("bx not fitted"))
    assert line == ("bx not fitted: the file's offset on that axis does not change with "
                    "temperature (no thermal compensation there); held at 0: no change with "
                    "temperature above the noise on this axis")
    p = px4_params(fw.text)
    assert [p[f"TC_A0_X{j}_0"] for j in range(4)] == [0.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("kw,words", [
    ({"degree": 4}, "offset polynomial is cubic"),
    ({"source": "chamber_c"}, "fitted on chamber_c"),
])
@pytest.mark.parametrize("fmt", ["px4", "ardupilot"])
def test_models_the_firmware_would_apply_wrongly_are_refused(tmp_path, capsys, kw, words, fmt):
    _, text, code = _export(tmp_path, _model(**kw), fmt)
    assert code == 2 and text == ""
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1


def _firmware_offset_g(fmt: str, text: str, temp_c: np.ndarray,
                       cal_temp_c: float = 27.0) -> np.ndarray:
    """(N, 3) g: the offset the firmware's own formula subtracts at ``temp_c`` (ArduPilot's
    less its value at ``cal_temp_c``, INS_ACCn_CALTEMP).

    The formula is a function of the reading alone, so it is run once per distinct reading
    and handed back per sample: a 1 °C channel's 90 000 samples take a few dozen levels, and
    the per-sample loop of the firmware's formula was most of this file's CPU."""
    levels_c, which = np.unique(np.asarray(temp_c, float), return_inverse=True)
    zero = np.zeros((levels_c.size, 3))
    if fmt == "px4":
        per_level = -_px4_correct(px4_params(text), zero, levels_c) / G
    else:
        per_level = -_ap_correct(ardupilot_params(text), zero, levels_c, cal_temp_c) / G
    return per_level[which.reshape(-1)]


def _figures(line: str, what: str) -> np.ndarray:
    """The three x / y / z numbers after ``what`` in an export's line (mg)."""
    return np.array([float(v) for v in line.split(what)[1].split(" mg")[0].split(" / ")])


@pytest.mark.parametrize("fmt", ["px4", "ardupilot"])
def test_a_model_fitted_in_a_rebuilt_temperature_says_what_the_firmware_will_do(
        tmp_path, capsys, fmt):
    """A warm-up read by a 1 °C channel: the model is fitted in the die temperature rebuilt
    from the channel's crossings, but the firmware evaluates its offset at its own 1 °C
    reading. The export's figure is checked here with each firmware's own formula applied
    at the raw reading against the same formula at the rebuilt temperature."""
    from types import SimpleNamespace

    from calibration import cli
    from calibration.captures import warmup_rebuild
    from calibration.recording import write_recording
    from tests.calibration.dequantise_cases import warmup_rows as _warmup_rows

    rec, _ = _warmup_rows(1.0)
    src, model = tmp_path / "w.csv", tmp_path / "model.json"
    write_recording(src, rec.columns)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model),
                                             json=True)) == 0
    capsys.readouterr()
    out = tmp_path / f"out.{fmt}"
    assert main(["export", str(model), "--format", fmt, "-o", str(out)]) == 0
    text, err = out.read_text(), capsys.readouterr().err
    read_c = rec.temperature_c()
    rebuilt_c = warmup_rebuild(rec)[0].temperature_c()
    at_read = _firmware_offset_g(fmt, text, read_c) * 1e3
    # the model's own offset at the rebuilt temperature: what `compensate` subtracts
    fitted = load_model(model)
    lo, hi = fitted.valid_c
    at_rebuilt = fitted.params_vector_at(np.clip(rebuilt_c, lo, hi))[:, :3] * 1e3
    diff_mg = at_read - at_rebuilt
    diff_mg -= diff_mg.mean(axis=0)  # the constant is X0's / INS_ACCOFFS', not the file's
    rms, peak = np.sqrt(np.mean(diff_mg**2, axis=0)), np.max(np.abs(diff_mg), axis=0)
    # z warms by 1 mg/°C: the firmware's step values leave about 1 mg/°C × 0.29 °C RMS
    assert 0.2 < rms[2] < 0.4 and 0.4 < peak[2] <= 0.7
    said = [x for x in err.splitlines() if "at its own 1 degC reading" in x]
    assert len(said) == 1 and "this file's polynomial is in that reading" in said[0]
    np.testing.assert_allclose(_figures(said[0], "by RMS "), rms, atol=0.0015)
    np.testing.assert_allclose(_figures(said[0], ", peak "), peak, atol=0.0015)
    # several times the fit's own error: said loudly, first in the header and on stderr
    assert said[0].startswith("WARNING: the firmware's 1 degC temperature reading")
    fit_mg = _figures(said[0], "the fit's own held-out RMS is ")
    ratio = float(said[0].split("cost up to ")[1].split(" x")[0])
    assert ratio == pytest.approx(np.max(rms / fit_mg), rel=0.05) and ratio > 3
    first = [x for x in text.splitlines() if x.startswith("#")][1]
    assert first.startswith("# WARNING: the firmware's 1 degC temperature reading")
    assert "soakcal compensate" in said[0]


def test_the_firmware_reading_is_said_quietly_when_it_costs_little() -> None:
    from calibration.export_firmware import LOUD_FACTOR, quantised_reading_lines

    record = {"lsb_c": 1.0, "readings": 100, "rms_mg": [0.01, 0.02, 0.03],
              "peak_mg": [0.02, 0.04, 0.06], "tempco_lsb_mg": [0.03, 0.07, 0.1],
              "fit_heldout_mg": [0.05, 0.05, 0.05], "ratio_to_fit": 0.6}
    (line,) = quantised_reading_lines(record)
    assert not line.startswith("WARNING") and "RMS 0.010 / 0.020 / 0.030 mg" in line
    (loud,) = quantised_reading_lines({**record, "ratio_to_fit": LOUD_FACTOR})
    assert loud.startswith("WARNING")
    assert quantised_reading_lines(None) == []


def _quantised_warmup(profile, seed: int):
    """5-s capture means of a board at rest (z up) whose z bias is 1 mg/°C + 0.02 mg/°C² of
    its die temperature, read by a 1 °C channel; and that true bias (g)."""
    from tests.calibration.dequantise_cases import warmup_rows, z_bias_g

    rec, die = warmup_rows(1.0, profile, seed)
    return rec, z_bias_g(die)


@pytest.mark.parametrize("fmt", ["px4", "ardupilot"])
@pytest.mark.parametrize("profile", ["heat_cool", "overshoot"])
def test_the_exported_polynomial_is_the_best_one_at_the_firmware_reading(tmp_path, capsys,
                                                                         fmt, profile):
    """A model fitted in the temperature rebuilt from a 1 °C channel: the file's polynomial
    is fitted against the raw reading the firmware evaluates it at, and applied by the
    firmware's own formula at that reading it is closer to the true bias than the model's
    b(T) re-expanded (the export of a model file without the raw-reading polynomial), on a
    second warm-up of the same die trace with fresh noise. Both leave the within-step
    error that no polynomial in the reading removes (1 mg/°C × 0.29 °C RMS); the gain is
    where the log's mean bias at a reading is not b at that reading (measured 2-3 %)."""

    from benchmarks import bench_temperature_dequantise as traces

    rec, _ = _quantised_warmup(getattr(traces, profile), 5)
    src, path = _calibrated(tmp_path, rec)
    fitted = load_model(path)
    record = fitted.provenance["quantised_temperature"]
    capsys.readouterr()
    exported = {}
    for name in ("reading", "model"):
        if name == "model":  # as a model file without the raw-reading polynomial
            record.pop("raw_reading_bias_x_g", None)
            save_model(path, fitted)
        out = tmp_path / f"{name}.{fmt}"
        assert main(["export", str(path), "--format", fmt, "-o", str(out)]) == 0
        exported[name] = out.read_text()
    fresh, truth_g = _quantised_warmup(getattr(traces, profile), 11)

    def rms_mg(text: str) -> float:
        err = (_firmware_offset_g(fmt, text, fresh.temperature_c())[:, 2] - truth_g) * 1e3
        return float(np.sqrt(np.mean((err - err.mean()) ** 2)))  # X0 / INS_ACCOFFS: a constant

    reading, model_poly = rms_mg(exported["reading"]), rms_mg(exported["model"])
    assert 0.2 < reading < 0.99 * model_poly < 0.4


def _dithered_warmup(seed: int, rate_mg_per_c_per_min: float, noise_lsb: float = 0.4):
    """A board at rest (z up) heated then cooled (``heat_cool``), read at 50 Hz by a 1 °C
    channel dithered by ``noise_lsb`` of noise before rounding; its z bias 1 mg/°C of the
    die temperature plus ``rate_mg_per_c_per_min`` × dT/dt (a rate-sensitive part). Returns
    the 5-s capture means (``soakcal import --block-s 5``'s layout) and each sample's
    reading and capture index: what the firmware sees one sample at a time."""
    from benchmarks.bench_temperature_dequantise import heat_cool

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 1800.0, 1.0 / 50.0)
    die = heat_cool(t)
    reading = np.round(die + rng.normal(0.0, noise_lsb, t.size))
    rec, k, _ = _five_second_means(t, die, reading, rate_mg_per_c_per_min, rng)
    return rec, reading, k


@pytest.mark.parametrize("fmt", ["px4", "ardupilot"])
def test_the_stated_figure_of_a_dithered_channel_is_what_the_firmware_does(tmp_path, capsys,
                                                                          fmt):
    """A dithered 1 °C channel: the firmware evaluates the file's offset at each sample's
    reading, which flickers between levels (a capture mean of the reading is no reading it
    sees), and cannot apply the model's rate term k(T)·dT/dt. Measured here by the
    firmware's own formula at every sample's reading, averaged per capture, against the
    model's whole offset (``soakcal compensate`` of the same captures): the RMS the export
    states is within 20 % of it. Before, the stated figure was the bias alone at the
    capture-mean reading: 0.028 mg against 0.44 mg measured (now 0.451 against 0.449)."""


    rec, reading, capture = _dithered_warmup(5, 0.5)
    src, path = _calibrated(tmp_path, rec)
    assert load_model(path).temperature_rate  # the premise: the model keeps its rate term
    capsys.readouterr()
    out = tmp_path / f"out.{fmt}"
    assert main(["export", str(path), "--format", fmt, "-o", str(out)]) == 0
    text, err = out.read_text(), capsys.readouterr().err
    per_sample = _firmware_offset_g(fmt, text, reading)[:, 2]
    firmware_mg = np.bincount(capture, per_sample) / np.bincount(capture) * 1e3
    comp = tmp_path / "comp.csv"
    assert main(["compensate", str(path), str(src), "-o", str(comp), "--extrapolate"]) == 0
    with comp.open() as f:
        model_mg = np.array([float(r["az"]) - float(r["cz"]) for r in csv.DictReader(f)]) * 1e3
    diff = firmware_mg - model_mg
    measured = float(np.sqrt(np.mean((diff - diff.mean()) ** 2)))  # X0: a constant
    said = [x for x in err.splitlines() if "at its own 1 degC reading" in x]
    assert len(said) == 1
    stated = _figures(said[0], "by RMS ")[2]
    assert measured > 0.2  # the firmware is far from the model here: worth stating right
    assert stated == pytest.approx(measured, rel=0.2)


def _rate_warmup(seed: int, rate_mg_per_c_per_min: float):
    """A board at rest (z up) through ``rest_heat_rest`` (450 s at 20.3 °C, then a heating
    toward 30.3 °C, τ 300 s) at 50 Hz, read by a fine channel (0.01 °C of noise, 0.0078 °C
    LSB); its z bias 1 mg/°C of the die temperature plus ``rate_mg_per_c_per_min`` × dT/dt
    (a rate-sensitive part). Returns the 5-s capture means, each sample's reading and
    capture index, and each capture's true z offset (g)."""
    from benchmarks.bench_temperature_dequantise import rest_heat_rest

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 1500.0, 1.0 / 50.0)
    die = rest_heat_rest(t)
    reading = np.round((die + rng.normal(0.0, 0.01, t.size)) / 0.0078) * 0.0078
    rec, k, offset = _five_second_means(t, die, reading, rate_mg_per_c_per_min, rng)
    return rec, reading, k, offset


def test_the_rate_term_is_folded_into_the_file_as_the_warm_up_saw_it(tmp_path, capsys):
    """A warm-up whose model keeps a rate term k(T)·dT/dt, which neither firmware can apply.
    The file's polynomial is the least-squares fit in T of the model's whole offset on the
    fit log (the term's mean at each temperature folded in) instead of the model's b(T)
    alone (the term dropped, as a model file without the ``rate_fold`` record exports).
    Applied by each firmware's formula at every sample's reading of a second warm-up with
    the same thermal profile and fresh noise, averaged per capture, against the true
    offset: the folded file is closer. At rest it differs from b(T) by the folded part,
    which the header states: checked against the two files' own difference."""
    from types import SimpleNamespace

    from calibration import cli
    from calibration.recording import write_recording

    rec, _, _, _ = _rate_warmup(5, 0.5)
    src, folded = tmp_path / "w.csv", tmp_path / "folded.json"
    write_recording(src, rec.columns)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(folded),
                                             json=True)) == 0
    fitted = load_model(folded)
    assert fitted.temperature_rate  # the premise: the model keeps its rate term
    fitted.provenance.pop("rate_fold", None)
    dropped = tmp_path / "dropped.json"  # as a model file without the fold
    save_model(dropped, fitted)
    lo, hi = fitted.valid_c
    grid = np.linspace(lo, hi, 201)
    _, reading, capture, truth_g = _rate_warmup(11, 0.5)
    capsys.readouterr()
    for fmt in ("px4", "ardupilot"):
        files = {}
        for name, model in (("folded", folded), ("dropped", dropped)):
            out = tmp_path / f"{name}.{fmt}"
            assert main(["export", str(model), "--format", fmt, "-o", str(out)]) == 0
            files[name] = (out.read_text(), capsys.readouterr().err)
        rms = {}
        for name, (text, _) in files.items():
            per_sample = _firmware_offset_g(fmt, text, reading)[:, 2]
            err = (np.bincount(capture, per_sample) / np.bincount(capture) - truth_g) * 1e3
            rms[name] = float(np.sqrt(np.mean((err - err.mean()) ** 2)))  # X0: a constant
        assert rms["folded"] < 0.8 * rms["dropped"]
        # the stated difference at rest: the two files over TMIN..TMAX, about their mean
        text, err = files["folded"]
        said = [x for x in err.splitlines() if "FOLDED:" in x]
        # the file's error on the second warm-up, against the truth, is within what the
        # line states: its distance from the model on the fit log plus the model's own
        # held-out error (a fine channel: the line states both)
        in_sample = _figures(said[0], "from that whole offset by RMS ")[2]
        model_own = _figures(said[0], "as calibrate chose its degree) is ")[2]
        assert rms["folded"] <= in_sample + model_own
        assert len(said) == 1 and "DROPPED" not in err and "DROPPED" in files["dropped"][1]
        # what the folded file leaves of the rate term on the fit log is several times the
        # fit's own held-out error here: said loudly, first in the header
        first = [x for x in text.splitlines() if x.startswith("#")][1]
        assert first.startswith("# WARNING: the firmware cannot apply this warm-up's rate")
        diff = (_firmware_offset_g(fmt, text, grid)
                - _firmware_offset_g(fmt, files["dropped"][0], grid)) * 1e3
        diff -= diff.mean(axis=0)
        at_rest = said[0].split("by the folded part: ")[1]
        np.testing.assert_allclose(_figures(at_rest, "RMS "),
                                   np.sqrt(np.mean(diff**2, axis=0)), atol=0.0015)
        np.testing.assert_allclose(_figures(at_rest, "peak "), np.max(np.abs(diff), axis=0),
                                   atol=0.0015)


def _five_second_means(t: np.ndarray, die: np.ndarray, reading: np.ndarray,
                       rate_mg_per_c_per_min: float, rng: np.random.Generator):
    """A board at rest (z up) sampled at ``t``, its z offset 1 mg/°C of ``die`` about 27 °C
    plus ``rate_mg_per_c_per_min`` × dT/dt, 0.2 mg of noise per sample: its 5-s capture means
    (``soakcal import --block-s 5``'s layout) with ``reading`` as the temperature, each
    sample's capture index, and each capture's true z offset (g)."""
    from calibration.recording import Recording

    rate = np.gradient(die, t) * 60.0
    offset = 1e-3 * (die - 27.0) + 1e-3 * rate_mg_per_c_per_min * rate
    k = np.floor(t / 5.0).astype(int)
    n = np.bincount(k)

    def mean(x: np.ndarray) -> np.ndarray:
        return np.bincount(k, x) / n

    noise = rng.normal(0.0, 2e-4, (t.size, 3))
    cols = {"t_s": mean(t), "sensor_c": mean(reading), "ax": mean(noise[:, 0]),
            "ay": mean(noise[:, 1]), "az": mean(1.0 + offset + noise[:, 2]),
            "n": n.astype(float), "sd_x": np.full(n.size, 2e-4),
            "sd_y": np.full(n.size, 2e-4), "sd_z": np.full(n.size, 2e-4)}
    return Recording.from_columns(cols), k, mean(offset)


def test_the_ardupilot_file_is_fitted_at_the_reading_its_filter_hands_it(tmp_path, capsys):
    """A dithered 1 °C channel read through ArduPilot's InvenSense 1-Hz temperature filter
    (:func:`calibration.firmware_flight.ardupilot_reading_in_use`): the ArduPilot file,
    flown sample by sample by the firmware's own formula at the filtered reading and
    averaged per capture, is within 20 % of the figure its header states for that driver
    (against ``soakcal compensate``'s offset) and within 5 % of the best cubic in the
    filtered reading, fitted here on the same log. A file fitted at each sample's own
    flickering reading (the PX4 file's polynomial, and the ArduPilot file before) is
    1.7 × that best on this log."""

    from calibration.firmware_flight import ardupilot_reading_in_use

    rec, reading, capture = _dithered_warmup(5, 0.0)
    t_s = np.arange(0.0, 1800.0, 1.0 / 50.0)  # _dithered_warmup's samples
    src, path = _calibrated(tmp_path, rec)
    capsys.readouterr()
    out = tmp_path / "out.ardupilot"
    assert main(["export", str(path), "--format", "ardupilot", "-o", str(out)]) == 0
    text = out.read_text()
    comp = tmp_path / "comp.csv"
    assert main(["compensate", str(path), str(src), "-o", str(comp), "--extrapolate"]) == 0
    with comp.open() as f:
        model_mg = np.array([float(r["az"]) - float(r["cz"]) for r in csv.DictReader(f)]) * 1e3
    filtered = ardupilot_reading_in_use(t_s, reading)
    n = np.bincount(capture)
    flown_mg = np.bincount(capture, _firmware_offset_g("ardupilot", text, filtered)[:, 2]) \
        / n * 1e3
    diff = flown_mg - model_mg
    measured = float(np.sqrt(np.mean((diff - diff.mean()) ** 2)))  # a constant: INS_ACCOFFS
    p = ardupilot_params(text)
    clamped = np.clip(filtered, p["INS_TCAL1_TMIN"], p["INS_TCAL1_TMAX"])
    V = np.column_stack([np.bincount(capture, clamped**j) / n for j in range(4)])
    best = V @ np.linalg.lstsq(V, model_mg, rcond=None)[0] - model_mg
    best_rms = float(np.sqrt(np.mean(best**2)))
    assert measured <= 1.05 * best_rms
    said = [x for x in text.splitlines() if "InvenSense drivers (MPU" in x]
    assert len(said) == 1
    stated = _figures(said[0], "the reading, RMS ")[2]
    assert stated == pytest.approx(measured, rel=0.2)


def test_the_ardupilot_files_folded_figures_are_its_own(tmp_path, capsys):
    """A dithered 1 °C channel and a model that keeps a rate term k(T)·dT/dt: the ArduPilot
    file is fitted at the capture mean of the reading (where the InvenSense drivers' 1-Hz
    filter evaluates it) with the term's mean folded in. Its FOLDED line states that file's
    figures, read as a user reads them: at rest, the difference from the same model's file
    with the term dropped (the two files over TMIN..TMAX, about their mean); on the fit
    log, the file flown through the filter sample by sample, averaged per capture, against
    ``soakcal compensate``'s offset. Before, the line gave the per-sample (PX4) fold's
    figures in the ArduPilot file."""

    from calibration.firmware_flight import ardupilot_reading_in_use

    rec, reading, capture = _dithered_warmup(5, 0.5)
    t_s = np.arange(0.0, 1800.0, 1.0 / 50.0)  # _dithered_warmup's samples
    src, path = _calibrated(tmp_path, rec)
    fitted = load_model(path)
    # the premises: a rate term, folded at the filtered reading too
    assert fitted.temperature_rate
    assert fitted.provenance["rate_fold"].get("filtered_folded_rate_x_g") is not None
    fitted.provenance.pop("rate_fold")
    dropped = tmp_path / "dropped.json"
    save_model(dropped, fitted)
    lo, hi = fitted.valid_c
    capsys.readouterr()
    texts = {}
    for name, model in (("folded", path), ("dropped", dropped)):
        out = tmp_path / f"{name}.ardupilot"
        assert main(["export", str(model), "--format", "ardupilot", "-o", str(out)]) == 0
        texts[name] = out.read_text()
    said = [x for x in texts["folded"].splitlines() if "FOLDED:" in x]
    assert len(said) == 1
    grid = np.linspace(lo, hi, 201)
    diff = (_firmware_offset_g("ardupilot", texts["folded"], grid)
            - _firmware_offset_g("ardupilot", texts["dropped"], grid)) * 1e3
    diff -= diff.mean(axis=0)
    at_rest = said[0].split("by the folded part: ")[1]
    np.testing.assert_allclose(_figures(at_rest, "RMS "), np.sqrt(np.mean(diff**2, axis=0)),
                               atol=0.0015)
    np.testing.assert_allclose(_figures(at_rest, "peak "), np.max(np.abs(diff), axis=0),
                               atol=0.0015)
    comp = tmp_path / "comp.csv"
    assert main(["compensate", str(path), str(src), "-o", str(comp), "--extrapolate"]) == 0
    with comp.open() as f:
        model_mg = np.array([float(r["az"]) - float(r["cz"]) for r in csv.DictReader(f)]) * 1e3
    filtered = ardupilot_reading_in_use(t_s, reading)
    flown_mg = np.bincount(capture, _firmware_offset_g("ardupilot", texts["folded"],
                                                       filtered)[:, 2]) \
        / np.bincount(capture) * 1e3
    off = flown_mg - model_mg
    measured = float(np.sqrt(np.mean((off - off.mean()) ** 2)))  # a constant: INS_ACCOFFS
    stated = _figures(said[0], "from that whole offset by RMS ")[2]
    assert stated == pytest.approx(measured, rel=0.2)


def test_the_ardupilot_file_is_written_for_the_boards_driver(tmp_path, capsys):
    """A dithered 1 °C channel: ArduPilot's InvenSense drivers filter the reading at 1 Hz,
    its ICM-42xxx and BMI088 drivers hand ``INS_TCAL`` each sample's reading. Each driver's
    file (``--temperature-reading filtered|per-sample``), flown by the firmware's own
    formula at the reading that driver hands it and averaged per capture, is nearer
    ``soakcal compensate``'s offset than the other driver's file flown the same way; the
    per-sample file is the PX4 file's polynomial (the same offset up to a constant), and
    each header names the drivers it is for. PX4 reads no filtered temperature: asking it
    for one is refused with the reason."""

    from calibration.firmware_flight import ardupilot_reading_in_use

    rec, reading, capture = _dithered_warmup(5, 0.0)
    t_s = np.arange(0.0, 1800.0, 1.0 / 50.0)  # _dithered_warmup's samples
    src, path = _calibrated(tmp_path, rec)
    comp = tmp_path / "comp.csv"
    assert main(["compensate", str(path), str(src), "-o", str(comp), "--extrapolate"]) == 0
    with comp.open() as f:
        model_mg = np.array([float(r["az"]) - float(r["cz"]) for r in csv.DictReader(f)]) * 1e3
    capsys.readouterr()
    texts = {}
    for how in ("filtered", "per-sample"):
        out = tmp_path / f"{how}.ardupilot"
        assert main(["export", str(path), "--format", "ardupilot", "--temperature-reading",
                     how, "-o", str(out)]) == 0
        texts[how] = out.read_text()
    hands = {"filtered": ardupilot_reading_in_use(t_s, reading), "per-sample": reading}
    n = np.bincount(capture)

    def flown_rms_mg(file: str, driver: str) -> float:
        off = np.bincount(capture, _firmware_offset_g("ardupilot", texts[file],
                                                      hands[driver])[:, 2]) / n * 1e3
        diff = off - model_mg
        return float(np.sqrt(np.mean((diff - diff.mean()) ** 2)))  # constant: INS_ACCOFFS

    for driver, other in (("filtered", "per-sample"), ("per-sample", "filtered")):
        assert flown_rms_mg(driver, driver) < flown_rms_mg(other, driver)
    assert "fitted for ArduPilot's InvenSense drivers" in texts["filtered"]
    assert "fitted for ArduPilot's ICM-42xxx (Invensensev3) and BMI088" in \
        texts["per-sample"]
    px4 = tmp_path / "out.params"
    assert main(["export", str(path), "--format", "px4", "-o", str(px4)]) == 0
    grid = np.linspace(*load_model(path).valid_c, 101)
    gap = _firmware_offset_g("ardupilot", texts["per-sample"], grid) \
        - _firmware_offset_g("px4", px4.read_text(), grid)
    assert np.ptp(gap, axis=0).max() < 1e-7  # g: float32 parameters
    capsys.readouterr()
    refused = tmp_path / "refused.params"
    assert main(["export", str(path), "--format", "px4", "--temperature-reading", "filtered",
                 "-o", str(refused)]) == 2
    err = capsys.readouterr().err
    assert "PX4 evaluates TC_A* at the unfiltered reading" in err
    assert not refused.exists()
