"""Firmware export: the C header compiled with the system compiler agrees with Python.

The double function must match :meth:`ThermalModel.compensate` (what ``soakcal
compensate`` computes) within 0.1 µg over the valid range; the float twin
within the bound the header states (``export.FLOAT_BOUND_UG``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import thermal_sim

from calibration import export
from calibration.export_cli import run_export
from calibration.model_file import load_model, save_model
from calibration.thermal import fit_campaign

CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")

DRIVER = r"""
#include <stdio.h>
#include "soakcal_cal.h"
int main(void) {
    double r[3], t, o[3];
    float rf[3], of[3];
    while (scanf("%lf %lf %lf %lf", &r[0], &r[1], &r[2], &t) == 4) {
        int s = soakcal_compensate(r, t, o);
        rf[0] = (float)r[0]; rf[1] = (float)r[1]; rf[2] = (float)r[2];
        int sf = soakcal_compensate_f(rf, (float)t, of);
        printf("%d %.17g %.17g %.17g %d %.9g %.9g %.9g\n", s, o[0], o[1], o[2],
               sf, (double)of[0], (double)of[1], (double)of[2]);
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def model_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    _, rec = thermal_sim.campaign(seed=5)
    path = tmp_path_factory.mktemp("export") / "model.json"
    save_model(path, fit_campaign(rec).model)
    return path


def _export(model: Path, fmt: str, out: Path) -> int:
    return run_export(argparse.Namespace(model=str(model), format=fmt, output=str(out)))


def _compile(header_dir: Path) -> Path:
    (header_dir / "driver.c").write_text(DRIVER)
    exe = header_dir / "driver"
    proc = subprocess.run(
        [CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-I", str(header_dir),
         str(header_dir / "driver.c"), "-o", str(exe), "-lm"],
        capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    return exe


@pytest.mark.skipif(CC is None, reason="no C compiler (cc/gcc/clang) on PATH")
def test_c_header_matches_python_compensation(model_file: Path, tmp_path: Path) -> None:
    header = tmp_path / "soakcal_cal.h"
    assert _export(model_file, "c", header) == 0
    assert header.read_text(encoding="utf-8").isascii()  # embedded toolchains: ASCII only
    exe = _compile(tmp_path)
    model = load_model(model_file)
    lo, hi = model.valid_c
    rng = np.random.default_rng(3)
    n = 2000
    v = rng.normal(size=(n, 3))
    raw = v / np.linalg.norm(v, axis=1, keepdims=True) * rng.uniform(0.5, 1.5, (n, 1))
    temp = np.r_[rng.uniform(lo, hi, n - 4), lo, hi, lo - 5.0, hi + 5.0]
    stdin = "\n".join(f"{a:.17g} {b:.17g} {c:.17g} {t:.17g}"
                      for (a, b, c), t in zip(raw, temp, strict=True))
    proc = subprocess.run([str(exe)], input=stdin, capture_output=True, text=True, check=True)
    got = np.array([[float(x) for x in line.split()] for line in proc.stdout.splitlines()])
    assert got.shape == (n, 8)
    expected = model.compensate(raw, temp, extrapolate=True)
    err_d_ug = np.abs(got[:, 1:4] - expected).max() * 1e6
    err_f_ug = np.abs(got[:, 5:8] - expected).max() * 1e6
    print(f"max |C - Python|: double {err_d_ug:.2e} µg, float {err_f_ug:.3f} µg")
    assert err_d_ug < 0.1, err_d_ug
    assert err_f_ug < export.FLOAT_BOUND_UG, err_f_ug
    inside = (temp >= lo) & (temp <= hi)
    np.testing.assert_array_equal(got[:, 0], np.where(inside, 0, 1))
    np.testing.assert_array_equal(got[:, 4], np.where(inside, 0, 1))


def test_json_flat_recipe_reproduces_compensation(model_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "flat.json"
    assert _export(model_file, "json-flat", out) == 0
    doc = json.loads(out.read_text())
    assert doc["format"] == "soakcal-flat" and doc["version"] == 1
    model = load_model(model_file)
    c = np.array(doc["coefficients"])
    raw = np.array([0.01, -0.99, 0.05])
    T = 0.5 * (doc["valid_low_c"] + doc["valid_high_c"]) + 3.0
    x = (T - doc["t_centre_c"]) / doc["t_scale_c"]
    p = c @ x ** np.arange(c.shape[1])  # the documented recipe, step by step
    v = (raw - p[0:3]) * p[3:6]
    C = np.array([[1, 0, 0], [p[6], 1, 0], [p[7], p[8], 1]])

    def rot(a: float, axis: int) -> np.ndarray:
        cs, sn = np.cos(a), np.sin(a)
        i, j = [k for k in range(3) if k != axis]
        R = np.eye(3)
        R[i, i] = R[j, j] = cs
        R[i, j], R[j, i] = (-sn, sn) if axis != 1 else (sn, -sn)
        return R

    out_g = rot(p[11], 2) @ rot(p[10], 1) @ rot(p[9], 0) @ (C @ v)
    np.testing.assert_allclose(out_g, model.compensate(raw, T)[0], atol=1e-12)


def test_bad_model_file_exits_2_with_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture, model_file: Path
) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "soakcal-model", "version": 1}')
    out = tmp_path / "out.h"
    assert _export(bad, "c", out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.json" in err
    assert not out.exists()
    assert _export(tmp_path / "missing.json", "c", out) == 2
    assert not out.exists()
    assert _export(model_file, "fortran", out) == 2
    assert not out.exists()
    before = model_file.read_text()
    assert _export(model_file, "c", model_file) == 2  # -o equal to the model: refused
    assert model_file.read_text() == before
    assert _export(tmp_path, "c", out) == 2  # a directory: one line, no traceback
    assert not out.exists()


def test_model_with_extension_terms_is_refused(model_file: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    doc = json.loads(model_file.read_text())
    doc["extensions"] = [{"kind": "discrepancy.scale_nonlinearity"}]
    ext = tmp_path / "ext.json"
    ext.write_text(json.dumps(doc))
    assert _export(ext, "c", tmp_path / "x.h") == 2
    assert "extensions" in capsys.readouterr().err
    assert not (tmp_path / "x.h").exists()


@pytest.mark.skipif(CC is None, reason="no C compiler (cc/gcc/clang) on PATH")
def test_temperature_independent_model_ignores_temperature(tmp_path: Path) -> None:
    from calibration.recording import Recording

    _, rec = thermal_sim.campaign(seed=6, setpoints=(25.0,))
    cols = {k: v for k, v in rec.columns.items() if k not in ("sensor_c", "setpoint_c")}
    cols["chamber_c"] = np.full(len(rec), np.nan)
    model = fit_campaign(Recording.from_columns(cols)).model
    assert not model.temperature_dependent
    save_model(tmp_path / "m.json", model)
    assert _export(tmp_path / "m.json", "c", tmp_path / "soakcal_cal.h") == 0
    exe = _compile(tmp_path)
    raw = np.array([[0.02, -0.01, 0.98], [0.7, 0.7, 0.1]])
    stdin = "0.02 -0.01 0.98 nan\n0.7 0.7 0.1 200\n"
    proc = subprocess.run([str(exe)], input=stdin, capture_output=True, text=True, check=True)
    got = np.array([[float(x) for x in line.split()] for line in proc.stdout.splitlines()])
    np.testing.assert_array_equal(got[:, 0], [0, 0])  # no range to leave, NaN is fine
    np.testing.assert_allclose(got[:, 1:4], model.compensate(raw, np.nan), atol=1e-12)
    flat = tmp_path / "flat.json"
    assert _export(tmp_path / "m.json", "json-flat", flat) == 0
    doc = json.loads(flat.read_text())
    assert doc["temperature_dependent"] is False and doc["valid_low_c"] is None


FILTER_DRIVER = r"""
#include <stdio.h>
#include "soakcal_cal.h"
int main(void) {
    soakcal_tfilter f;
    double t, y;
    soakcal_tfilter_init(&f);
    while (scanf("%lf %lf", &t, &y) == 2) {
        printf("%.17g\n", soakcal_tfilter_update(&f, t, y));
    }
    return 0;
}
"""


@pytest.mark.skipif(CC is None, reason="no C compiler (cc/gcc/clang) on PATH")
def test_header_streaming_filter_matches_the_python_causal_filter(
    model_file: Path, tmp_path: Path
) -> None:
    from calibration.temperature_conditioning import causal_filter

    assert _export(model_file, "c", tmp_path / "soakcal_cal.h") == 0
    (tmp_path / "filt.c").write_text(FILTER_DRIVER)
    exe = tmp_path / "filt"
    subprocess.run([CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I",
                    str(tmp_path), str(tmp_path / "filt.c"), "-o", str(exe), "-lm"],
                   check=True, capture_output=True)
    rng = np.random.default_rng(9)
    t = np.cumsum(rng.uniform(0.5, 30.0, 3000))
    y = np.where(t < 20_000, 25.0, 60.0 - (t - 20_000) / 120.0)  # plateau, then a ramp
    y = y + rng.normal(0, 0.1, t.size)
    y[500] += 30.0  # a spike
    y[1500:] += 10.0  # a jump
    y[2000] = np.nan
    stdin = "\n".join(f"{a:.17g} {b:.17g}" for a, b in zip(t, y, strict=True))
    proc = subprocess.run([str(exe)], input=stdin, capture_output=True, text=True, check=True)
    got = np.array([float(v) for v in proc.stdout.split()])
    want = causal_filter(t, y)
    np.testing.assert_allclose(got, want, atol=1e-9, equal_nan=True)
