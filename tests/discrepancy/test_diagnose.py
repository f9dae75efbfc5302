"""Issue 5: each effect found on a clear case, not on a null, hidden where the protocol hides it."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.discrepancy import diagnose
from calibration.discrepancy.effects import ALL_EFFECTS, BY_ID
from calibration.recording import Recording
from calibration.schedules import six_position
from simulators import effects as E  # noqa: N812 (short name for many effects)
from simulators.campaign_sim import RigPhysics, simulate_campaign
from simulators.truth import SensorTruth

N_NULL = 30
ONE_WAY = [float(t) for t in range(-40, 61, 10)]
UP_DOWN = [-40.0, -20.0, 0.0, 20.0, 40.0, 60.0, 50.0, 30.0, 10.0, -10.0, -30.0]
# A seeded order per plateau: a function of the specific force is then told from a settling
# at each slot of the visiting order (in one order on every plateau it is not named).
VARIED = {"position_order": "random", "position_order_seed": 3}


def run(effects=(), *, setpoints=ONE_WAY, seed=1, **kw):
    truth = SensorTruth.adxl355_typical(seed=seed, effects=list(effects))
    rec = simulate_campaign(truth, setpoints_c=setpoints, seed=seed + 10, **kw)
    return diagnose(rec, n_null=N_NULL, seed=seed)


def found(diag) -> list[str]:
    return [f.effect for f in diag.findings]


def hidden(diag) -> set[str]:
    return {n["effect"] for n in diag.not_identifiable}


@pytest.fixture(scope="module")
def null_one_way():
    return run(seed=3)


@pytest.fixture(scope="module")
def null_up_down():
    return run(setpoints=UP_DOWN, seed=4)


def test_every_catalogue_effect_has_a_module():
    ids = {"thermal_lag", "thermal_hysteresis", "temperature_rate", "scale_nonlinearity",
           "cross_coupling", "turntable_geometry", "lever_arm", "filter_delay", "bias_drift",
           "session_offset", "self_heating", "vibration_rectification", "temperature_sensor",
           "local_gravity", "outlier"}
    assert ids == set(BY_ID)
    for eff in ALL_EFFECTS:
        assert callable(eff.identifiable) and callable(eff.sentence) and eff.experiment


def test_nulls_have_no_findings(null_one_way, null_up_down):
    for d in (null_one_way, null_up_down):
        assert not d.mismatch and d.findings == []
        assert d.rmse_ug == pytest.approx(d.noise_ug, rel=0.25)


def test_static_protocol_hides_motion_and_gravity(null_one_way):
    assert {"lever_arm", "filter_delay", "local_gravity"} <= hidden(null_one_way)


def test_scale_nonlinearity_found_with_parameter():
    d = run([E.ScaleNonlinearity(k2_per_g=np.array([0.0, 0.0, 80e-6]))], **VARIED)
    assert found(d)[0] == "scale_nonlinearity"
    f = d.findings[0]
    assert f.axes == ["z"]
    assert f.parameters["k2_z_ug_per_g2"] == pytest.approx(80.0, abs=5 * f.parameter_sd[
        "k2_z_ug_per_g2"])
    assert f.heldout_rmse_after_ug < f.heldout_rmse_before_ug
    assert "square" in f.explanation and "µg/g²" in f.explanation


def test_hysteresis_found_on_up_down_and_hidden_one_way():
    eff = E.ThermalHysteresis(h_g=np.array([25e-6, 0.0, 0.0]))
    d = run([eff], setpoints=UP_DOWN, seed=5)
    assert found(d)[0] == "thermal_hysteresis"
    assert d.findings[0].parameters["h_x_ug"] == pytest.approx(25.0, abs=6.0)
    d1 = run([eff], setpoints=ONE_WAY, seed=5)
    assert "thermal_hysteresis" not in found(d1)
    assert "thermal_hysteresis" in hidden(d1)


def test_bias_drift_found_on_up_down_and_hidden_one_way():
    eff = E.BiasDrift(rate_g_per_h=np.array([0.0, 4e-6, 0.0]))
    d = run([eff], setpoints=UP_DOWN, seed=6)
    assert found(d)[0] == "bias_drift"
    assert d.findings[0].axes == ["y"]
    d1 = run([eff], setpoints=ONE_WAY, seed=6)
    assert "bias_drift" not in found(d1) and "bias_drift" in hidden(d1)


def test_thermal_lag_found_on_chamber_and_hidden_with_sensor_c():
    lag = E.ThermalLag(tau_s=1500.0)
    d = run(physics=lag.physics(RigPhysics()), temperature_columns=lag.COLUMNS, seed=7)
    assert found(d)[0] == "thermal_lag"
    assert d.findings[0].parameters["tau_s"] == pytest.approx(1500.0, rel=0.35)
    assert d.findings[0].heldout_rmse_after_ug < 0.5 * d.findings[0].heldout_rmse_before_ug
    d1 = run(physics=lag.physics(RigPhysics()), seed=7)  # sensor_c recorded: the die itself
    assert "thermal_lag" not in found(d1) and "thermal_lag" in hidden(d1)


def test_outlier_found_and_located():
    d = run([E.Outlier(size_g=np.array([0.0, 250e-6, 0.0]), rows=(77,))], seed=8)
    assert found(d)[0] == "outlier"
    f = d.findings[0]
    assert f.rows == [77] and f.where["positions"] == [77 % 24]
    assert f.heldout_rmse_after_ug <= f.heldout_rmse_before_ug


def test_cross_coupling_found_and_hidden_axis_aligned():
    d = run([E.CrossCoupling(k_xy_per_g=60e-6)], seed=9, **VARIED)
    assert found(d)[0] == "cross_coupling"
    d1 = run([E.CrossCoupling(k_xy_per_g=60e-6)], seed=9, schedule=six_position(), **VARIED)
    assert "cross_coupling" not in found(d1) and "cross_coupling" in hidden(d1)


def test_session_offset_found():
    """On this one-way staircase the plateaus after the power cycle are the hot ones: with
    the cycle logged in a session column it is named; without, a jump of the output at a
    temperature fits it as well (temperature_jump.py) and it is reported not separable."""
    sessions = [0] * 5 + [1] * 6
    truth = SensorTruth.adxl355_typical(seed=10, effects=[
        E.SessionOffset(offsets_g=np.array([[0, 0, 0], [0, 0, 40e-6]]))])
    rec = simulate_campaign(truth, setpoints_c=ONE_WAY, seed=20, sessions=sessions)
    logged = Recording.from_columns({**rec.columns, "session": np.repeat(
        np.array(sessions, float), np.bincount(rec.columns["step"].astype(int)))})
    d = diagnose(logged, n_null=N_NULL, seed=10)
    assert found(d)[0] == "session_offset"
    assert d.findings[0].axes == ["z"]
    d = diagnose(rec, n_null=N_NULL, seed=10)
    f = d.findings[0]
    assert f.effect == "not_identifiable" and f.where["candidates"][0] == "session_offset"
    assert "jump of the output" in f.where["candidates"][1]
    assert min(f.where["steps"]) == 5


def test_vibration_rectification_found():
    # The down leg's warm plateaus vibrate more than the up leg's: a vibration power that is
    # not a function of temperature alone. Where it is (cold plateaus only) a jump of the
    # output at a temperature fits it as well (test_temperature_jump.py). 40 per g: at 30 this
    # draw led a bias drift by 5.6 noise variances, short of by_fit.MARGIN (χ²₁ at 1 − 2α,
    # 6.63), and is reported not separable from it; at 40 it leads by 20.7.
    vib = tuple(3e-3 if t < 0 else (1.5e-3 if i >= 6 else 0.5e-3)
                for i, t in enumerate(UP_DOWN))
    d = run([E.VibrationRectification(c_per_g=np.array([40.0, 0.0, 0.0]))], seed=11,
            setpoints=UP_DOWN, physics=RigPhysics(vib_sd_g_by_step=vib))
    assert "vibration_rectification" in found(d)
    # Its column (sd² ≈ 1e-5 g²) is far smaller than the base's: the fit must not drop it.
    f = d.findings[found(d).index("vibration_rectification")]
    assert f.parameters["c_x_per_g"] == pytest.approx(40.0, abs=4 * f.parameter_sd["c_x_per_g"])
    assert f.heldout_rmse_after_ug < f.heldout_rmse_before_ug


def test_cli_json_contract(tmp_path, capsys):
    import json
    from types import SimpleNamespace

    from calibration.discrepancy.cli import run_diagnose
    from calibration.recording import write_recording

    truth = SensorTruth.adxl355_typical(seed=12, effects=[
        E.ScaleNonlinearity(k2_per_g=np.array([70e-6, 0.0, 0.0]))])
    path = tmp_path / "run.csv"
    write_recording(path, simulate_campaign(truth, seed=13, **VARIED))
    rep = tmp_path / "rep"
    args = SimpleNamespace(recording=str(path), model=None, json=True, report_dir=str(rep),
                           seed=0, n_null=N_NULL)
    assert run_diagnose(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) >= {"recording", "baseline", "mismatch", "findings", "not_identifiable"}
    assert doc["baseline"]["model"] == "sfem-cubic"
    assert isinstance(doc["baseline"]["rmse_ug"], float) and doc["baseline"]["noise_ug"] > 0
    assert doc["mismatch"] is True
    f = doc["findings"][0]
    assert set(f) >= {"effect", "axes", "where", "explanation", "parameters", "rmse_before_ug",
                      "rmse_after_ug", "heldout_rmse_before_ug", "heldout_rmse_after_ug",
                      "evidence"}
    assert f["effect"] == "scale_nonlinearity" and f["axes"] == ["x"]
    assert set(f["where"]) >= {"steps", "positions", "time_s"} and len(f["where"]["time_s"]) == 2
    assert set(f["evidence"]) == {"test", "p_value"} and f["evidence"]["p_value"] < 0.01
    for n in doc["not_identifiable"]:
        assert set(n) == {"effect", "why", "experiment"}
    assert (rep / "residuals_time.png").exists() and (rep / "diagnosis.json").exists()


def test_cli_bad_input_exit_2(tmp_path, capsys):
    from types import SimpleNamespace

    from calibration.discrepancy.cli import run_diagnose

    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,ax,ay,az,chamber_c\n0,0,0,1,abc\n", encoding="utf-8")
    args = SimpleNamespace(recording=str(bad), model=None, json=True, report_dir=None, seed=0,
                           n_null=N_NULL)
    assert run_diagnose(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.csv" in err[0]


def test_twin_reproduces_finding():
    from simulators.effects import to_truth_effects

    d = run([E.ScaleNonlinearity(k2_per_g=np.array([0.0, 90e-6, 0.0]))], seed=14, **VARIED)
    effs = to_truth_effects(d)
    assert [e.effect_id for e in effs] == ["scale_nonlinearity"]
    assert effs[0].k2_per_g[1] == pytest.approx(90e-6, abs=10e-6)
    # The same from the JSON findings (what a twin file carries).
    again = to_truth_effects(d.to_dict()["findings"])
    assert again[0].k2_per_g[1] == effs[0].k2_per_g[1]


def test_calibration_never_imports_simulators():
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[2] / "calibration"
    offenders = [str(p) for p in root.rglob("*.py")
                 if "from simulators" in p.read_text() or "import simulators" in p.read_text()]
    assert offenders == []


def test_extended_model_compensates_better():
    from calibration.discrepancy.extensions import extension_specs
    from calibration.thermal import fit_campaign

    truth = SensorTruth.adxl355_typical(seed=21, effects=[
        E.ScaleNonlinearity(k2_per_g=np.array([0.0, 0.0, 150e-6]))])
    rec = simulate_campaign(truth, seed=22, **VARIED)
    d = diagnose(rec, n_null=N_NULL, seed=0)
    model = fit_campaign(rec).model
    T = rec.temperature_c()

    def rms_ug(m):
        return float(np.sqrt(np.mean((m.compensate(rec.raw_g, T) - rec.ref_g) ** 2)) * 1e6)

    before = rms_ug(model)
    model.extensions = list(model.extensions) + extension_specs(d)
    assert [e["kind"] for e in model.extensions] == ["discrepancy.scale_nonlinearity"]
    after = rms_ug(model)
    assert after < 0.5 * before


def test_real_openaxes_norm_mode():
    from realdata import need_realdata

    from calibration.importers import import_static

    src = need_realdata("openaxes-adxl355/log_imu9_2022-06-22_22-13-55.csv")
    _, _, rec = import_static("openaxes", src)
    d = diagnose(rec, n_null=50, seed=0)
    assert d.mode == "norm" and d.heldout_scheme.startswith("leave-one-interval-out")
    assert d.rmse_ug > 2.5 * d.noise_ug  # the linear fit sits well above its noise floor
    assert found(d) == ["scale_nonlinearity"]
    f = d.findings[0]
    assert f.heldout_rmse_after_ug < 0.5 * f.heldout_rmse_before_ug
    assert {"thermal_lag", "thermal_hysteresis", "local_gravity"} <= hidden(d)
