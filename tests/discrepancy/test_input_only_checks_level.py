"""The input-only checks at their level where plateaus are whitened unevenly (issue 22).

An input-only term (``scale_nonlinearity``, ``cross_coupling``) is named only if the same
reference direction leaves the same residual at every visit (``structure.visits_differ``)
and no free offset per direction is still needed after it
(``scale_nonlinearity.direction_offsets_needed``). Both tests' columns, whitened, weigh the
quiet plateaus more than the vibrating ones. On the second generator the noise model
whitens a recording's quiet plateaus to 0.9–1.0 of unit variance and its vibrating ones to
0.7–0.8; an F test with one noise scale for the recording then read the quiet plateaus'
ordinary scatter as structure (at 5 %: 7.2 % and 8.3 % of 600 nulls). The checks scale each
plateau by its own residual scale (``structure.log_p_by_plateau``): here, with that uneven
whitening exaggerated (quiet 1.0, vibrating 0.25 in variance), they reject pure noise at
about their level where the pooled F does not.

Noise pools are synthetic (``uneven_staircase``, as test_channel_step_time_check_level.py).
"""

from __future__ import annotations

import importlib

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID, scale_nonlinearity, structure
from calibration.discrepancy.effects.structure import log_p, log_p_by_plateau
from calibration.discrepancy.problem import build_problem
from tests.discrepancy.uneven_staircase import loud_sd, uneven_staircase

diagnose_mod = importlib.import_module("calibration.discrepancy.diagnose")
BEND = BY_ID["scale_nonlinearity"]
STAIRCASE_C = (50.0, 40.0, 30.0, 20.0, 10.0, 0.0, -10.0, -20.0)
LOUD_FROM = 4  # plateaus from here on vibrate
ALPHA_CHECK = 0.05
DRAWS = 60


def _problem():
    pb = build_problem(uneven_staircase(STAIRCASE_C, "sparse18", LOUD_FROM))
    term = diagnose_mod.Term("scale_nonlinearity", 0.0,
                             pb.lift(BEND.regressors(pb.ctx, 0.0)))
    U, _ = diagnose_mod._basis(pb, [term])
    return pb, U, loud_sd(pb, LOUD_FROM)


def _visit_columns(pb, U):
    """visits_differ's test: the per-visit offsets after the per-direction ones."""
    ctx = pb.ctx
    common, visit = [], []
    for g in structure.direction_groups(ctx.positions, ctx.input_g):
        common.append(structure.per_axis_indicator(ctx.n, np.isin(ctx.positions, g)))
        visit += [structure.per_axis_indicator(ctx.n, ctx.positions == p) for p in g]
    Uc = structure.extend(U, np.zeros(pb.m), structure.whitened(
        pb, np.concatenate(common, axis=2)))[0]
    return Uc, structure.whitened(pb, np.concatenate(visit, axis=2))


def _disagreeing_draw(pb, U, Ut, Xw, sd, rng):  # type: ignore[no-untyped-def]
    """A draw of unevenly whitened noise (after ``U``) on which the by-plateau test of
    ``Xw`` after ``Ut`` and the pooled F differ by more than a factor e in p: the draw, the
    by-plateau log p, and a level between the two p values."""
    for _ in range(200):
        e = stats.project_out(U, sd * rng.standard_normal(pb.m))
        et = e - Ut @ (Ut.T @ e)
        lp_q, _ = log_p_by_plateau(pb, Ut, et, Xw)
        lp_f, _ = log_p(Ut, et, Xw)
        if abs(lp_q - lp_f) > 1.0:
            break
    return e, lp_q, float(np.exp(0.5 * (lp_q + lp_f)))


def test_the_visit_test_reads_each_plateau_at_its_own_scale():
    """At 5 %, 60 draws of pure noise whitened unevenly: scaled by plateau at most 8
    (13 %; a test at its level stays at or below that in 99.7 % of runs), the pooled F more
    than 12 (20 %)."""
    pb, U, sd = _problem()
    Uc, Xw = _visit_columns(pb, U)
    rng = np.random.default_rng(1)
    hits = np.zeros(2, int)
    for _ in range(DRAWS):
        e = stats.project_out(Uc, sd * rng.standard_normal(pb.m))
        for i, (lp, k) in enumerate((log_p_by_plateau(pb, Uc, e, Xw), log_p(Uc, e, Xw))):
            hits[i] += int(k > 0 and lp <= np.log(ALPHA_CHECK))
    assert hits[0] <= 8
    assert hits[1] > 12


def test_the_checks_use_it():
    """``visits_differ`` and ``direction_offsets_needed`` answer as the by-plateau test:
    on draws where it and the pooled F disagree at a level, their verdicts are its."""
    pb, U, sd = _problem()
    Uc, Xw = _visit_columns(pb, U)
    rng = np.random.default_rng(2)
    e, lp_q, level = _disagreeing_draw(pb, U, Uc, Xw, sd, rng)
    found = structure.visits_differ(pb, U, e, [], ["x", "y", "z"], level)
    assert (found is None) == (lp_q > np.log(level))
    # The free offset per direction, after the term and a turn of the reference.
    ctx = pb.ctx
    from calibration.discrepancy.effects.turntable_geometry import turn_columns

    u = ctx.input_g / np.linalg.norm(ctx.input_g, axis=1, keepdims=True)
    dirs = structure.direction_ids(ctx.positions, ctx.input_g)
    Xd = np.concatenate([structure.per_axis_indicator(ctx.n, np.flatnonzero(dirs == j))
                         for j in range(int(dirs.max()) + 1)], axis=2)
    Ut, _ = structure.extend(U, e, structure.whitened(pb, turn_columns(u)))
    e, lp_q, level = _disagreeing_draw(pb, U, Ut, structure.whitened(pb, Xd), sd, rng)
    found = scale_nonlinearity.direction_offsets_needed(pb, U, e, (0, 1, 2), level, "a², a³")
    assert (found is None) == (lp_q > np.log(level))
