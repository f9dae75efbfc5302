"""The family test calibrates each kind of null on itself before the minimum (issue 22).

The outlier family's replicates are parametric; the other families' are sign flips of the
recording's own residual, whose analytic p runs heavier than nominal on heavy-tailed
recordings. The minimum of the raw p over all families let the heavier null decide: on the
second generator an outlier at p = 4·10⁻⁵, beyond all 400 of its own replicates, lost to two
replicates of a sign-flip family (p_family 3/401 > α/2).
"""

from __future__ import annotations

import importlib

import numpy as np

from calibration.discrepancy import family_level
from calibration.discrepancy.level import ALPHA, N_NULL
from calibration.discrepancy.stats import CandidateTest

diagnose_mod = importlib.import_module("calibration.discrepancy.diagnose")


def _uniform_logp(rng: np.random.Generator, b: int) -> np.ndarray:
    """log of b p-values spread as a uniform's quantiles, in a random order."""
    return np.log(rng.permutation(np.arange(1, b + 1) / (b + 1)))


def _test(eid: str, logp_obs: float, logp_null: np.ndarray) -> CandidateTest:
    return CandidateTest(eid, logp_obs, 1, logp_obs, logp_null, float("nan"), 0.0, 0.0)


def _outlier_and_heavy_sign_flips(power: float) -> dict[str, CandidateTest]:
    """An outlier at p = 4·10⁻⁵ against a nominal null, and a sign-flip family whose
    analytic p is the nominal p to the power ``power`` (a heavier null) with its recording
    at p = 0.3."""
    rng = np.random.default_rng(22)
    return {"outlier": _test("outlier", np.log(4e-5), _uniform_logp(rng, N_NULL)),
            "scale_nonlinearity": _test("scale_nonlinearity", np.log(0.3),
                                        power * _uniform_logp(rng, N_NULL))}


def _raw_minimum_p(tests: dict[str, CandidateTest]) -> float:
    """The family test as a minimum of the raw p over all families (before issue 22)."""
    lmin_null = np.min(np.vstack([t.logp_adj_null for t in tests.values()]), axis=0)
    best = min(t.logp_adj for t in tests.values())
    return (1 + int(np.sum(lmin_null <= best))) / (N_NULL + 1)


def test_an_outlier_beyond_its_own_null_is_not_decided_by_a_heavier_null():
    tests = _outlier_and_heavy_sign_flips(power=2.0)
    assert _raw_minimum_p(tests) > ALPHA / 2  # what the raw minimum gave: lost
    best, p_family = diagnose_mod._family_p(tests, N_NULL)
    assert best.effect_id == "outlier"
    assert p_family <= ALPHA / 2


def test_a_heavier_null_still_calibrates_its_own_family():
    """The sign-flip family's own recording at its heavy null's extreme is not called: its
    p is judged against that null, not the nominal one."""
    tests = _outlier_and_heavy_sign_flips(power=2.0)
    heavy = tests["scale_nonlinearity"]
    tests["outlier"] = _test("outlier", np.log(0.5), tests["outlier"].logp_adj_null)
    # at the heavy null's 1 % point: p = 0.01² = 10⁻⁴, nominally significant, not here
    tests["scale_nonlinearity"] = _test("scale_nonlinearity", 2.0 * np.log(0.01),
                                        heavy.logp_adj_null)
    _, p_family = diagnose_mod._family_p(tests, N_NULL)
    assert p_family > 0.005


def test_the_family_wise_level_against_the_replicates_themselves():
    """Each replicate in turn as the recording (the map is symmetric in the B + 1 values):
    the share called at α/2 stays at α/2, with a heavy family and a nominal one."""
    rng = np.random.default_rng(5)
    called = drawn = 0
    for _ in range(40):
        L = np.vstack([np.log(rng.uniform(size=N_NULL + 1)),
                       2.0 * np.log(rng.uniform(size=N_NULL + 1)),
                       1.5 * np.log(rng.uniform(size=N_NULL + 1))])
        Q = np.vstack([family_level.own_null_logq(row) for row in
                       (L[0], L[1:].min(axis=0))])
        p = np.exp(family_level.tail_logq(Q.min(axis=0)))
        called += int(np.sum(p <= ALPHA / 2))
        drawn += p.size
    # binomial: at the nominal 0.25 % of 16 040 draws the count is 40 ± 6.3
    assert called / drawn <= ALPHA / 2 + 2 * np.sqrt(ALPHA / 2 / drawn)
