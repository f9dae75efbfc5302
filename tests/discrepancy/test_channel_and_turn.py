"""Issue 22: a step of the temperature channel is found; a turn of the reference is not
given a nonlinearity's name (it is reported as not separable from the table's geometry)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.discrepancy import diagnose
from simulators import effects as E  # noqa: N812 (short name for many effects)
from simulators.campaign_sim import simulate_campaign
from simulators.truth import SensorTruth

ONE_WAY = [float(t) for t in range(-40, 61, 10)]


def test_a_step_of_the_temperature_channel_is_found_with_its_size_and_plateau():
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=5), setpoints_c=ONE_WAY, seed=15)
    col = rec.temperature_source
    rec.columns[col] = rec.columns[col] + np.where(rec.steps() >= 6, 0.5, 0.0)
    d = diagnose(rec, n_null=30, seed=5)
    assert [f.effect for f in d.findings] == ["temperature_sensor"]
    f = d.findings[0]
    assert f.parameters["from_step"] == 6.0
    assert f.parameters["step_c"] == pytest.approx(0.5, abs=4 * f.parameter_sd["step_c"])
    assert "reads +0.51" in f.explanation and "from step 6 on" in f.explanation


def test_the_unstepped_channel_gives_no_finding():
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=5), setpoints_c=ONE_WAY, seed=15)
    assert diagnose(rec, n_null=30, seed=5).findings == []


def test_a_tilted_table_is_not_named_a_nonlinearity():
    tilt = E.TurntableGeometry(base_tilt_rad=np.array([3e-3, -2e-3]))
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=6, effects=[tilt]),
                            setpoints_c=ONE_WAY, seed=16)
    d = diagnose(rec, n_null=30, seed=6)
    named = [f.effect for f in d.findings]
    assert not {"scale_nonlinearity", "cross_coupling"} & set(named)
    turned = [f for f in d.findings if f.effect == "not_identifiable"]
    assert turned and all("turntable_geometry" in f.where["candidates"] for f in turned)
    assert "without changing its length" in turned[0].explanation
    assert "record the gimbal angles" in turned[0].explanation
    assert "turntable_geometry" in {n["effect"] for n in d.not_identifiable}


def test_a_real_nonlinearity_keeps_its_name():
    nl = E.ScaleNonlinearity(k2_per_g=np.array([0.0, 0.0, 80e-6]))
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=1, effects=[nl]),
                            setpoints_c=ONE_WAY, seed=11)
    d = diagnose(rec, n_null=30, seed=1)
    assert d.findings[0].effect == "scale_nonlinearity"



def test_a_channel_that_settles_within_the_plateaus_is_not_called_a_step():
    """A re-seated probe that settles over each plateau (1 °C, τ 15 min, from step 6 on):
    its error changes with time within the plateaus, which a step cannot do."""
    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=5), setpoints_c=ONE_WAY, seed=15)
    col, steps, t = rec.temperature_source, rec.steps(), rec.t_s
    since = np.zeros_like(t)
    for s in np.unique(steps):
        since[steps == s] = t[steps == s] - t[steps == s].min()
    rec.columns[col] = rec.columns[col] + np.where(steps >= 6, 1 - np.exp(-since / 900.0), 0.0)
    d = diagnose(rec, n_null=30, seed=5)
    assert [f.effect for f in d.findings] == ["unexplained"]
    assert "not a step" in d.findings[0].explanation


def test_soakcal_diagnose_reads_the_recording_once(tmp_path, monkeypatch, capsys):
    """The gate and the diagnosis share one read of the file (issue 22)."""
    import json
    from types import SimpleNamespace

    import calibration.cli as top
    import calibration.recording as recording_mod
    from calibration.recording import write_recording

    rec = simulate_campaign(SensorTruth.adxl355_typical(seed=5), setpoints_c=ONE_WAY[:6],
                            seed=15)
    src = tmp_path / "r.csv"
    write_recording(src, rec.columns)
    reads: list[str] = []
    real = recording_mod.read_recording

    def counted(path, *a, **k):
        reads.append(str(path))
        return real(path, *a, **k)

    monkeypatch.setattr(recording_mod, "read_recording", counted)
    monkeypatch.setattr(top, "read_recording", counted)
    args = SimpleNamespace(recording=str(src), json=True, model=None, n_null=20,
                           against=None, write_twin=None, report_dir=None, seed=1)
    assert top.run_diagnose(args) == 0
    assert reads == [str(src)]
    assert json.loads(capsys.readouterr().out)["verdict"] != "cannot judge"
