"""Detector settings chosen by leave-one-interval-out error (calibration/static_choice.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from calibration import importers, schedules, static_choice
from calibration.fit import fit_norm
from calibration.importers_cli import run_import
from simulators.truth import SensorTruth
from tests.realdata import need_realdata

XSENS = "imu_tk-xsens/xsens_acc.mat"


def _settling_raw(seed: int = 0, n_pos: int = 20, settle_g: float = 4e-3) -> importers.RawImport:
    """Rest, then ``n_pos`` hand placements of 4 s; each starts with a slow settling offset.

    The offset (``settle_g``, decaying with τ = 0.25 s) is smooth, so the variance
    detector calls it static: only a trim removes it.
    """
    rng = np.random.default_rng(seed)
    truth = SensorTruth.adxl355_typical(seed).params_at(25.0)
    rate = 100.0
    dirs = schedules.sphere(n_pos)
    t, acc = [], []
    t0 = 0.0

    def seg(dur: float) -> np.ndarray:
        return t0 + np.arange(int(round(dur * rate))) / rate

    tt = seg(10.0)
    t.append(tt)
    acc.append(np.tile(truth.invert(dirs[:1])[0], (tt.size, 1)))
    t0 += 10.0
    for v in dirs:
        tt = seg(1.5)
        t.append(tt)
        acc.append(np.column_stack([np.sin(5 * tt), np.cos(4 * tt), np.sin(3 * tt)]) * 0.7)
        t0 += 1.5
        tt = seg(4.0)
        settle = settle_g * np.exp(-(tt - tt[0]) / 0.25)[:, None] * rng.normal(0, 1, 3)
        t.append(tt)
        acc.append(truth.invert(v[None])[0] + settle)
        t0 += 4.0
    a = np.vstack(acc) + rng.normal(0, 1e-3, (sum(x.size for x in t), 3))
    return importers.RawImport("<synthetic>", "mpu6050", np.concatenate(t), a, 10.0)


def test_linearised_leave_one_out_equals_the_refits() -> None:
    rng = np.random.default_rng(1)
    truth = SensorTruth.adxl355_typical(1).params_at(25.0)
    raw = truth.invert(schedules.sphere(30)) + rng.normal(0, 200e-6, (30, 3))
    sig = np.full((30, 3), 20e-6)  # residuals ≫ σ: the floor comes into play too
    res = fit_norm(raw, sig)
    exact = []
    for i in range(30):
        keep = np.arange(30) != i
        r = fit_norm(raw[keep], sig[keep])
        exact.append(np.linalg.norm(r.params.apply(raw[i:i + 1])[0]) - 1.0)
    exact_ug = np.sqrt(np.mean(np.square(exact))) * 1e6
    assert static_choice.press_ug(res, raw, sig) == pytest.approx(exact_ug, rel=0.02)


def test_settling_edges_make_the_choice_trim_them() -> None:
    raw = _settling_raw()
    base = importers.DEFAULT_DETECTOR["mpu6050"]
    choice = static_choice.choose_detector(raw, base)
    assert choice.chosen_by == "leave-one-out"
    assert choice.settings.trim_s > 0.0
    untrimmed = importers.find_intervals(raw, importers.DetectorSettings(
        window_s=base.window_s, threshold=choice.settings.threshold,
        min_duration_s=base.min_duration_s, trim_s=0.0))
    assert choice.loo_ug < static_choice.exact_loo_ug(raw, untrimmed)
    assert len(choice.intervals) >= 20  # nothing dropped to get there
    assert "leave-one-interval-out" in choice.summary()


def test_flags_override_and_one_flag_fixes_one_dimension() -> None:
    raw = _settling_raw(seed=2)
    base = importers.DetectorSettings(window_s=1.0, threshold=10.0, min_duration_s=1.5,
                                      trim_s=0.0)
    both = static_choice.choose_detector(raw, base, fixed=frozenset({"threshold", "trim_s"}))
    assert both.chosen_by == "flags" and both.settings == base
    one = static_choice.choose_detector(raw, base, fixed=frozenset({"threshold"}))
    assert one.settings.threshold == 10.0
    assert {c.threshold for c in one.candidates} == {10.0}


def test_too_few_intervals_keep_the_defaults_and_say_why() -> None:
    raw = _settling_raw(n_pos=8)
    choice = static_choice.choose_detector(raw, importers.DEFAULT_DETECTOR["mpu6050"])
    assert choice.chosen_by == "defaults" and choice.loo_ug is None
    assert "13 intervals" in choice.reason


def test_run_import_reports_the_choice(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    xsens = need_realdata(XSENS)
    out = tmp_path / "x.csv"
    ns = argparse.Namespace(format="imu_tk", raw_path=str(xsens), output=str(out),
                            min_static_s=None, threshold=10.0, trim_s=0.0, raw=False)
    assert run_import(ns) == 0
    assert "threshold 10x, trim 0 s (flags)" in capsys.readouterr().out


def test_xsens_choice_is_no_worse_than_imu_tk() -> None:
    raw = importers.read_source("imu_tk", need_realdata(XSENS))
    choice = static_choice.choose_detector(raw, importers.DEFAULT_DETECTOR["imu_tk"])
    # imu_tk on its own data: 0.135 mg leave-one-interval-out (docs/realdata.md).
    assert choice.loo_ug is not None and choice.loo_ug <= 135.0
    assert choice.default_loo_ug is not None and choice.loo_ug < choice.default_loo_ug
