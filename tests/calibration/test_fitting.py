"""The one fit entry (calibration/fitting.py): its typed result, its decisions, its refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
import thermal_sim

from calibration import gate
from calibration.fitting import CalibrationFit, FitOptions, OptionNotApplicable, fit
from calibration.plateaus import segment_recording
from calibration.recording import Recording


@pytest.fixture(scope="module")
def soak() -> CalibrationFit:
    _, rec = thermal_sim.campaign(seed=11, setpoints=(-20.0, 20.0, 60.0))
    return fit(rec)


def test_a_soak_campaign_gives_one_typed_result_with_units_errors_and_convergence(
        soak: CalibrationFit) -> None:
    assert (soak.kind, soak.mode, soak.method) == ("sfem", "reference", "joint")
    assert soak.converged and soak.nfev > 0 and soak.message.startswith("joint fit: ")
    names = [p.name for p in soak.parameters]
    assert names[:3] == ["bx", "by", "bz"] and len(names) == 12
    units = {p.name: p.unit for p in soak.parameters}
    assert (units["bx"], units["sx"], units["mz"]) == ("g", "1", "rad")
    for p in soak.parameters:  # reference mode: every parameter fitted, with an error
        assert p.fitted and p.why == "fitted"
        assert len(p.coeffs) == soak.model.degree + 1 == 3  # three steps: degree 2
        assert all(math.isfinite(s) and s > 0 for s in p.stderr)
    bx = soak.parameters[0]
    assert abs(bx.value) < 0.05  # g: a bias, not a scale
    assert bx.value == pytest.approx(soak.model.params_at(soak.model.t_centre_c).bias_g[0])
    assert soak.valid_c == soak.model.valid_c and soak.valid_c[0] < -20.0 < 60.0 < soak.valid_c[1]
    # Eq. 9 after the model: rms over steps, and each used row's |compensated| − g
    per_step = [st.rmse_polynomial_ug for st in soak.steps]
    assert soak.rmse_ug == pytest.approx(float(np.sqrt(np.mean(np.square(per_step)))))
    assert soak.residuals_ug.shape == (len(soak.recording),)
    assert 3.0 < float(np.sqrt(np.mean(soak.residuals_ug**2))) < 30.0  # ~10 µg of noise
    assert soak.notes[0] == soak.reason and "distinct orientation" in soak.reason
    assert soak.report["orientations"] == soak.orientations
    assert soak.model.provenance["gravity"]["g_local"] == soak.model.g_local
    with pytest.raises(AttributeError):
        soak.rmse_ug = 0.0  # type: ignore[misc]  # frozen


def test_a_warm_up_is_a_warm_up_and_refuses_a_rate_gain() -> None:
    _, rec = thermal_sim.campaign(seed=11, setpoints=(-20.0, 0.0, 20.0, 40.0, 60.0))
    one = rec.columns["position"] == rec.columns["position"][0]
    warm = Recording.from_columns({k: v[one] for k, v in rec.columns.items()
                                   if not k.startswith("ref_")})
    result = fit(warm)
    assert (result.kind, result.mode, result.method) == ("warmup", "warmup", "warmup")
    assert [p.name for p in result.parameters if p.fitted] == ["bx", "by", "bz"]
    assert "held at 1" in result.held["sx"]
    assert result.residuals_ug.shape == (len(warm), 3)
    with pytest.raises(OptionNotApplicable, match="not applied to a warm-up") as exc:
        fit(warm, FitOptions(rate_gain_ug_per_c_per_min=(1.0, 2.0, 3.0)))
    assert exc.value.option == "rate_gain_ug_per_c_per_min"


def _creeping(rec: Recording, bend_c: float) -> Recording:
    """Each step's die creeping 0.3 °C over the sweep (the tail of a soak), plus a
    parabolic bend of ``bend_c`` in the middle of the sweep."""
    cols = dict(rec.columns)
    temp = cols["sensor_c"].copy()
    for s in np.unique(cols["step"]):
        idx = np.flatnonzero(cols["step"] == s)
        u = np.linspace(0.0, 1.0, idx.size)
        temp[idx] += 0.3 * u + bend_c * 4.0 * u * (1.0 - u)
    cols["sensor_c"] = temp
    return Recording.from_columns(cols)


def test_a_soak_at_a_held_setpoint_stays_a_step_while_its_die_follows_a_line() -> None:
    _, rec = thermal_sim.campaign(seed=11, setpoints=(-20.0, 20.0, 60.0))
    creeping = _creeping(rec, 0.0)
    seg = segment_recording(creeping)
    assert not seg.is_continuous and len(seg.plateau_ids) == 3
    # the same creep with step numbers only: no held setpoint, the excursion test drops it
    numbered = Recording.from_columns({k: v for k, v in creeping.columns.items()
                                       if k != "setpoint_c"})
    assert segment_recording(numbered).continuous_rows == len(rec)
    # a soak whose die bends away from its line is not described by it: continuous rows
    bent = segment_recording(_creeping(rec, 0.3))
    assert bent.continuous_rows == len(rec)
    assert "3 soak(s) at a held setpoint are fitted as continuous rows" in bent.notes[0]


def test_the_minimum_orientation_counts_come_from_the_freed_parameters() -> None:
    # norm mode frees 9 (Eq. 3), reference mode 12 at 3 residuals per orientation (Eq. 4)
    assert (gate.NORM_MIN_ORIENTATIONS, gate.REFERENCE_MIN_ORIENTATIONS) == (10, 4)
    from calibration.plateaus import MIN_POSITIONS_NORM, MIN_POSITIONS_REFERENCE

    assert (MIN_POSITIONS_NORM, MIN_POSITIONS_REFERENCE) == (12, 5)
    assert gate.min_orientations("reference", 4) == 6  # ⌈16 / 3⌉
