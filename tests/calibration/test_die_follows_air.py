"""Swapped temperature columns: the air moves through its plateaus while the die holds
(calibration/die_follows_air.py). ``calibrate`` and ``compensate`` refuse with the cause and
the fix, ``diagnose`` answers "cannot judge" with the same reason; a die still approaching
each setpoint (the columns right), a settled die and a ramp (both moving) are not refused.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from calibration import cli, gate
from calibration.die_follows_air import die_leads_air
from calibration.recording import Recording, write_recording
from tests.calibration.test_audit_campaigns import _campaign, _run

Columns = dict[str, np.ndarray]


def _approaching(cols: Columns, tau_s: float = 600.0, behind_c: float = 4.0) -> Columns:
    """The die still approaching each setpoint through its plateau: ``behind_c`` off at the
    step's first reading (on the side it came from), decaying with ``tau_s``."""
    out = {k: v.copy() for k, v in cols.items()}
    for s in np.unique(out["step"]):
        m = out["step"] == s
        t0 = out["t_s"][m][0]
        side = -1.0 if s > 0 else 1.0  # heating after the first step, from above before
        out["sensor_c"][m] += side * behind_c * np.exp(-(out["t_s"][m] - t0) / tau_s)
    return out


def _swapped(cols: Columns) -> Columns:
    return {**cols, "sensor_c": cols["chamber_c"].copy(), "chamber_c": cols["sensor_c"].copy()}


def test_swapped_columns_are_refused_by_calibrate_and_diagnose(tmp_path, capsys) -> None:
    err, reason = _run(tmp_path, _swapped(_approaching(_campaign())), capsys)
    assert "chamber_c moves through its plateaus while sensor_c holds" in err
    assert "on 3 of 3 steps" in err
    assert "the two columns look swapped" in err
    assert "write the die's temperature as sensor_c" in err
    assert "chamber_c moves through its plateaus" in reason


def test_swapped_columns_are_refused_by_compensate(tmp_path, capsys) -> None:
    right = _approaching(_campaign())
    good, model = tmp_path / "good.csv", tmp_path / "good.json"
    write_recording(good, right)
    assert cli.run_calibrate(SimpleNamespace(recording=str(good), output=str(model))) == 0
    capsys.readouterr()
    bad, out = tmp_path / "bad.csv", tmp_path / "out.csv"
    write_recording(bad, _swapped(right))
    assert cli.run_compensate(SimpleNamespace(
        model=str(model), recording=str(bad), output=str(out))) == 2
    err = capsys.readouterr().err
    assert "the two columns look swapped" in err and "nothing written" in err
    assert not out.exists()


def test_a_die_approaching_the_held_air_is_not_refused() -> None:
    assert die_leads_air(Recording.from_columns(_approaching(_campaign()))) is None


def test_a_settled_die_swapped_says_nothing() -> None:
    """Neither column moves through a plateau: which is which cannot be seen (and a constant
    difference is absorbed by the polynomial in T)."""
    assert die_leads_air(Recording.from_columns(_swapped(_campaign()))) is None


def test_a_ramp_where_both_move_is_not_refused() -> None:
    """The air ramps through each "step" and the die trails it by 60 s: both move."""
    cols = _campaign()
    rate_c_per_s = 0.5 / 60.0
    t0 = {s: cols["t_s"][cols["step"] == s][0] for s in np.unique(cols["step"])}
    since_s = cols["t_s"] - np.array([t0[s] for s in cols["step"]])
    cols["chamber_c"] = cols["setpoint_c"] + rate_c_per_s * since_s
    cols["sensor_c"] = cols["chamber_c"] - rate_c_per_s * 60.0 + 3.0
    rec = Recording.from_columns(cols)
    assert die_leads_air(rec) is None
    gate.check_temperature_channels(rec)
    with pytest.raises(gate.GateRefusal, match="look swapped"):
        swapped = _approaching(_campaign())
        gate.check_temperature_channels(Recording.from_columns(_swapped(swapped)))


def test_one_odd_plateau_is_not_enough(tmp_path: Path) -> None:
    """A chamber probe touched on one plateau moves the air there alone: not a swap."""
    cols = _campaign()
    m = cols["step"] == 1
    cols["chamber_c"][m] += np.linspace(0.0, 1.0, int(m.sum()))
    assert die_leads_air(Recording.from_columns(cols)) is None
