"""benchmarks/blind/plateau_share.py: what its injected nulls report as the test that fired.

The diagnosis JSON carries findings and the localised scan, not the stage log: the column
must be read from those, else every flagged null was listed as "other" (issue 22).
"""

import json

import numpy as np

from benchmarks.blind.plateau_share import _fired, plateau_variance


def test_fired_names_the_findings_and_the_scan_from_the_json():
    d = {"mismatch": True,
         "findings": [{"effect": "not_identifiable"}, {"effect": "unexplained"}],
         "unexplained": {"test": "localised scan", "significant": True}}
    assert _fired(json.loads(json.dumps(d))) == "not_identifiable+unexplained+scan"
    d["unexplained"]["significant"] = False
    assert _fired(d) == "not_identifiable+unexplained"
    assert _fired({"findings": [], "unexplained": None}) == "other"


def test_plateau_variance_finds_a_shared_offset_and_none_in_white_noise():
    rng = np.random.default_rng(3)
    k, per = 10, 12
    group = np.repeat(np.arange(k), per)
    U = np.ones((k * per, 1)) / np.sqrt(k * per)
    white = rng.standard_normal(k * per)
    shared = white + 1.0 * rng.standard_normal(k)[group]
    e0, e1 = white - U @ (U.T @ white), shared - U @ (U.T @ shared)
    assert plateau_variance(e0, U, group)["p"] > 0.01
    assert plateau_variance(e1, U, group)["p"] < 1e-3
