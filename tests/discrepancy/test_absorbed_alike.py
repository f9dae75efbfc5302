"""An effect the base absorbs (not tested) whose remnant is a not-identifiable finding's
structure is among that finding's candidates (issue 22, absorbed_alike.py).

The third generator's seed-1 case 17 with a rectified vibration at twice its detectable
size: five plateaus heated one way, where c·σ²_vib is a per-plateau offset that a cubic in
T absorbs 99.2 %. Its remnant is the one degree of freedom per axis a cubic leaves across
five plateaus, which "a change confined to step 2" and a power cycle also take; the
finding said those two and not the vibration the report listed as absorbed.
"""

from __future__ import annotations

import json

from benchmarks.blind.gen3.case import draw_case, simulate
from benchmarks.blind.gen3.effects import draw_effect
from benchmarks.blind.gen3.run import case_seed, diagnose_json
from benchmarks.blind.gen3.writer import write_csv


def test_an_absorbed_vibration_is_named_among_the_candidates_of_its_structure(tmp_path):
    drawn, info = draw_effect("vibration_rectification", draw_case(case_seed(1, 17)), 2.0)
    assert not info["absorbed"]  # gen3 draws it: its remnant is 2× detectable
    path = tmp_path / "case.csv"
    write_csv(simulate(drawn.case, drawn), path)
    doc = diagnose_json(path)
    listed = {n["effect"]: n["why"] for n in doc["not_identifiable"]}
    assert listed["vibration_rectification"].startswith("the base model absorbs 99.")
    found = [f for f in doc["findings"] if f["effect"] == "not_identifiable"]
    assert len(found) == 1, json.dumps(doc["findings"])[:500]
    assert found[0]["where"]["candidates"] == [
        "a change confined to step 2 (7 °C)", "session_offset", "vibration_rectification"]
    assert ("would leave this structure too: vibration_rectification (99 % of it; the base "
            "model absorbs 99.2 % of vibration_rectification here, so only an effect of that "
            "kind about 12× this structure's size would leave it)"
            in found[0]["explanation"])
