"""Each effect module owns its behaviour: no other module names effect ids (issue 10)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import calibration.discrepancy as pkg
from calibration.discrepancy.effects import ALL_EFFECTS, BY_ID
from calibration.discrepancy.effects.base import how_told_apart
from calibration.discrepancy.extensions import EXTENDING, KINDS
from calibration.extensions import apply_extensions

HERE = Path(pkg.__file__).parent


@pytest.mark.parametrize("name", ["diagnose.py", "extensions.py", "report.py"])
def test_no_catalogue_id_is_named_outside_its_module(name):
    code = (HERE / name).read_text(encoding="utf-8")
    for eid in BY_ID:
        assert not re.search(rf"[\"']{eid}[\"']", code), f"{name} names {eid!r}"


def test_told_apart_text_is_found_from_either_side():
    lag, hyst = BY_ID["thermal_lag"], BY_ID["thermal_hysteresis"]
    assert how_told_apart(lag, hyst) == how_told_apart(hyst, lag)
    assert "decays" in how_told_apart(hyst, lag)
    assert how_told_apart(BY_ID["outlier"], lag) == "compared by their p-values after projection"


def test_every_written_extension_kind_is_registered_by_its_module():
    assert set(KINDS) == {f"discrepancy.{e.effect_id}" for e in ALL_EFFECTS
                          if e.writes_extension}
    assert "discrepancy.outlier" not in KINDS and EXTENDING["discrepancy.thermal_lag"] is \
        BY_ID["thermal_lag"]


def test_extension_terms_remove_what_the_module_describes():
    a = np.array([[np.sqrt(0.5), np.sqrt(0.5), 0.0], [0.0, 0.0, 1.0]])
    raw, temp = np.zeros_like(a), np.full(2, 25.0)
    cc = {"kind": "discrepancy.cross_coupling", "k_xy_per_g": 100e-6}
    out = apply_extensions([cc], raw, temp, a.copy())
    # k_xy · a_x a_y = 50 µg on x and y at the 45° position, nothing on the axis-aligned one.
    assert out - a == pytest.approx(np.array([[-50e-6, -50e-6, 0.0], [0.0, 0.0, 0.0]]))
    hy = {"kind": "discrepancy.thermal_hysteresis", "h_g": [10e-6, 0.0, -4e-6], "direction": -1}
    assert apply_extensions([hy], raw, temp, a.copy()) - a == pytest.approx(
        np.tile([10e-6, 0.0, -4e-6], (2, 1)))
    drift = {"kind": "discrepancy.bias_drift", "rate_g_per_h": [1e-6, 0, 0]}
    assert np.array_equal(apply_extensions([drift], raw, temp, a.copy()), a)  # needs time


@pytest.mark.parametrize("eid, params", [
    ("scale_nonlinearity", {"k2_x_ug_per_g2": 30.0, "k2_y_ug_per_g2": -5.0,
                            "k2_z_ug_per_g2": 0.0, "k3_x_ug_per_g3": 0.0,
                            "k3_y_ug_per_g3": 12.0, "k3_z_ug_per_g3": -7.0}),
    ("cross_coupling", {"k_xy_ug_per_g2": 40.0, "k_xz_ug_per_g2": 0.0, "k_yz_ug_per_g2": -9.0}),
])
def test_model_file_term_is_the_tested_regressors(eid, params):
    """One place for the physics: the file's term is the diagnosis' columns × parameters."""
    from types import SimpleNamespace

    eff = BY_ID[eid]
    a = np.random.default_rng(0).normal(size=(20, 3))
    X = eff.regressors(SimpleNamespace(input_g=a, n=a.shape[0]), float("nan"))
    coef = np.array(list(params.values())) * 1e-6  # parameter order = column order
    spec = eff.extension_fields(params)
    assert eff.extension_term_g(spec, a) == pytest.approx(X @ coef, abs=1e-15)


def test_every_testable_effect_has_a_twin_counterpart():
    """The twin side (simulators, which import calibration, never the reverse) maps each
    finding by its id: an effect that can be named must have ``from_finding`` there."""
    from simulators.effects import EFFECT_CLASSES

    for eff in ALL_EFFECTS:
        has_twin = hasattr(EFFECT_CLASSES.get(eff.effect_id), "from_finding")
        assert has_twin == eff.observable, eff.effect_id
