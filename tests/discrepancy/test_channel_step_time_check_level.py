"""The channel step's time check at its level where plateaus are whitened unevenly (issue 22).

``temperature_sensor`` is named only if the output does not depart along ∂output/∂T with
time within the plateaus (``TemperatureSensor.misses``). That column lives on the plateaus
where ∂output/∂T is large against the noise: the quiet ones. On the second generator the
noise model whitens a recording's quiet plateaus to 0.9–1.0 of unit variance and its
vibrating ones to 0.7–0.8; a test taking one noise scale for the whole recording then read
the quiet plateaus' ordinary scatter as structure, and withheld a true step (gen2 seed 3
case 0139, p = 0.003 against the pooled scale, 0.013 by sign flips per reading). The check
reads the noise reading by reading (``structure.log_p_by_reading``): here, with the same
uneven whitening exaggerated (quiet 1.0, vibrating 0.25 in variance), it rejects pure noise
at about its level (18 of 400 at 5 %), where the pooled F rejects it 45 times.

Noise pools are synthetic (as test_temperature_sensor_power.py).
"""

from __future__ import annotations

import importlib

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.effects import BY_ID
from calibration.discrepancy.effects.structure import log_p, log_p_by_reading
from calibration.discrepancy.problem import build_problem
from tests.discrepancy.uneven_staircase import loud_sd, uneven_staircase

diagnose_mod = importlib.import_module("calibration.discrepancy.diagnose")
STEP = BY_ID["temperature_sensor"]
STAIRCASE_C = (50.0, 40.0, 30.0, 20.0, 10.0, 0.0, -10.0, -20.0, -30.0, -40.0)
FROM_STEP = 3
LOUD_FROM = 5  # plateaus at or below 0 °C vibrate (the generator's bench below 5 °C)
ALPHA_CHECK = 0.05
DRAWS = 400


def _problem():
    pb = build_problem(uneven_staircase(STAIRCASE_C, "oblique36", LOUD_FROM,
                                        effect="temperature_sensor", size=0.12,
                                        from_step=FROM_STEP))
    term = diagnose_mod.Term("temperature_sensor", float(FROM_STEP),
                             pb.lift(STEP.regressors(pb.ctx, float(FROM_STEP))))
    U, _ = diagnose_mod._basis(pb, [term])
    return pb, U


def _time_column_and_scale(pb) -> tuple[np.ndarray, np.ndarray]:
    """The check's time column (∂output/∂T times the time within each plateau, centred),
    whitened, and each whitened row's noise SD: 1 on the quiet plateaus, √LOUD_VARIANCE on
    the vibrating ones."""
    ctx = pb.ctx
    frac = np.zeros(ctx.n)
    for s in ctx.step_ids:
        m = ctx.steps == s
        frac[m] = ctx.time_since_step_s[m] / float(np.ptp(ctx.time_since_step_s[m])) - 0.5
    Xw = pb.whiten(pb.lift((ctx.draw_dtemp_g_per_c * frac[:, None])[:, :, None]))
    return Xw, loud_sd(pb, LOUD_FROM)


def _rejections(pb, U, test) -> int:
    """How often ``test`` rejects the time column at ALPHA_CHECK on pure noise whitened
    unevenly: variance 1 on the quiet plateaus, LOUD_VARIANCE on the vibrating ones."""
    Xw, sd = _time_column_and_scale(pb)
    rng = np.random.default_rng(1)
    hits = 0
    for _ in range(DRAWS):
        e = stats.project_out(U, sd * rng.standard_normal(pb.m))
        lp, k = test(pb, U, e, Xw)
        hits += int(k > 0 and lp <= np.log(ALPHA_CHECK))
    return hits


def test_the_time_check_reads_the_noise_reading_by_reading():
    """At a 5 % level, 400 draws: by reading at most 30 (7.5 %; a test at its level stays
    below that in 99 % of runs), where the pooled scale's F rejects more than 36 (9 %)."""
    pb, U = _problem()
    by_reading = _rejections(pb, U, log_p_by_reading)
    pooled = _rejections(pb, U, lambda pb, U, e, Xw: log_p(U, e, Xw))
    assert by_reading <= 30
    assert pooled > 36


def test_the_check_uses_it():
    """``TemperatureSensor.misses`` is the by-reading test: on one unevenly whitened draw
    its verdict at a level is the by-reading test's, not the pooled F's."""
    pb, U = _problem()
    Xw, sd = _time_column_and_scale(pb)
    rng = np.random.default_rng(2)
    for _ in range(200):
        e = stats.project_out(U, sd * rng.standard_normal(pb.m))
        lp_r, _ = log_p_by_reading(pb, U, e, Xw)
        lp_f, _ = log_p(U, e, Xw)
        level = float(np.exp(0.5 * (lp_r + lp_f)))  # between the two p values
        if abs(lp_r - lp_f) > 0.5:
            break
    miss = STEP.misses(pb, U, e, float(FROM_STEP), {}, ["x", "y", "z"], level)
    assert (miss is None) == (lp_r > np.log(level))
