"""Local gravity: WGS84 normal gravity against published values, and its use in calibrate."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest
import thermal_sim

from calibration.cli import run_calibrate
from calibration.gravity import GravityError, from_arguments, normal_gravity_m_s2
from calibration.model_file import load_model
from calibration.recording import Recording, recording_text
from calibration.thermal import fit_campaign


@pytest.mark.parametrize(
    ("lat", "h", "published"),
    [
        (0.0, 0.0, 9.7803253359),  # WGS84 gamma_e (NIMA TR8350.2 table 3.4)
        (90.0, 0.0, 9.8321849378),  # WGS84 gamma_p
        (45.0, 0.0, 9.8061977),  # the textbook "45 deg: 9.80620 m/s^2"
    ],
)
def test_normal_gravity_matches_published_values(lat: float, h: float, published: float) -> None:
    assert normal_gravity_m_s2(lat, h) == pytest.approx(published, abs=2e-7)


def test_free_air_gradient_is_about_minus_3086_ugal_per_m() -> None:
    slope = (normal_gravity_m_s2(45.0, 1000.0) - normal_gravity_m_s2(45.0, 0.0)) / 1000.0
    assert slope == pytest.approx(-3.086e-6, rel=2e-3)


def test_arguments_are_checked() -> None:
    assert from_arguments(None, None, None) is None
    assert from_arguments(1.0002, None, None).g == 1.0002
    lg = from_arguments(None, 45.0, None)
    assert lg.g == pytest.approx(9.8061977 / 9.80665, abs=1e-7) and "height 0 m" in lg.source
    for bad in ((9.81, None, None), (1.0, 45.0, None), (None, None, 100.0), (None, 91.0, 0.0),
                (None, 45.0, 1e6), (float("nan"), None, None)):
        with pytest.raises(GravityError):
            from_arguments(*bad)


def _calibrate(rec_path: Path, out: Path, **kw: object) -> int:
    ns = argparse.Namespace(recording=str(rec_path), output=str(out), json=True,
                            report_dir=None, method="per_step", **kw)
    return run_calibrate(ns)


def test_calibrate_scales_the_references_and_records_the_gravity(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    _, rec = thermal_sim.campaign(seed=7)
    path = tmp_path / "c.csv"
    path.write_text(recording_text(rec))
    assert _calibrate(path, tmp_path / "m1.json") == 0
    doc1 = json.loads(capsys.readouterr().out)
    assert _calibrate(path, tmp_path / "m2.json", latitude_deg=45.0, height_m=200.0) == 0
    doc2 = json.loads(capsys.readouterr().out)
    g = normal_gravity_m_s2(45.0, 200.0) / 9.80665
    assert doc2["gravity"]["g_local"] == pytest.approx(g) and doc2["g_local"] == pytest.approx(g)
    assert doc1["gravity"]["identifiable"] is False
    assert any("cannot be identified in a static tumble" in n for n in doc2["notes"])
    m1, m2 = load_model(tmp_path / "m1.json"), load_model(tmp_path / "m2.json")
    assert m2.g_local == pytest.approx(g) and m2.provenance["gravity"]["g_local"] == g
    # A enters the reference fit linearly: scale factors scale by g, the rest is unchanged
    p1, p2 = m1.params_at(10.0), m2.params_at(10.0)
    np.testing.assert_allclose(p2.scale, p1.scale * g, rtol=1e-9)
    np.testing.assert_allclose(p2.bias_g, p1.bias_g, atol=1e-9)
    np.testing.assert_allclose(p2.misalign_rad, p1.misalign_rad, atol=1e-9)


def test_norm_mode_fits_the_magnitude_to_the_local_gravity() -> None:
    _, rec = thermal_sim.campaign(seed=8)
    cols = {k: v for k, v in rec.columns.items() if not k.startswith("ref_")}
    norm_rec = Recording.from_columns(cols)
    fit1 = fit_campaign(norm_rec, method="per_step")
    m1 = fit1.model
    from calibration import report

    text = report.format_coefficients(fit1)  # misalignment is not fitted in norm mode
    assert "not fitted" in text and "mx   not identifiable" in text
    m2 = fit_campaign(norm_rec, method="per_step", g_local=1.0003).model
    assert m1.mode == m2.mode == "norm" and m2.g_local == 1.0003
    np.testing.assert_allclose(m2.params_at(10.0).scale, m1.params_at(10.0).scale * 1.0003,
                               rtol=1e-6)


def test_implausible_gravity_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "m.json"
    assert _calibrate(tmp_path / "whatever.csv", out, gravity_g=9.81) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--gravity-g" in err and "m/s²" in err
    assert not out.exists()
