"""``diagnose``: locate, explain, model and verify what the base model leaves out (issue 5).

Forward selection (docs/diagnosis.md §5): at each stage every identifiable
candidate effect is scored after projecting out the current model; the
smallest multiplicity-adjusted p-value is compared with its bootstrap null
(min over candidates → family-wise p; sign flips of the recording's own residual for the
families with columns, a parametric bootstrap for outliers: docs/diagnosis.md §2). The
winner is added only if it is significant at α/2 *and* improves the held-out RMS (whole
plateaus held out); then the rest are re-tested against a new null.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np

from calibration.discrepancy import absorbed_alike, by_fit, not_confirmed, stats, within_rounding
from calibration.discrepancy import one_step as one_step_report
from calibration.discrepancy import samples as samples_mod
from calibration.discrepancy import scan as scan_mod
from calibration.discrepancy.basis import RowBlockBasis, WhitenedDesign
from calibration.discrepancy.context import AXES
from calibration.discrepancy.effects import ALL_EFFECTS, BY_ID, CatalogueEffect, channel_glitch
from calibration.discrepancy.effects.base import how_told_apart
from calibration.discrepancy.effects.temperature_rate import lag_alike
from calibration.discrepancy.effects.turntable_geometry import TURNTABLE_GEOMETRY, turn_columns
from calibration.discrepancy.heldout import (
    column_scale,
    folds,
    heldout_rms_ug,
    heldout_rms_ug_by_blocks,
)
from calibration.discrepancy.level import ALPHA, N_NULL
from calibration.discrepancy.locate import locate_residuals, where_of
from calibration.discrepancy.one_step_fit import (
    one_plateau_fits_as_well,
    plateau_inputs,
    sfem_block,
)
from calibration.discrepancy.plateau_noise import (
    QuantisedChannel,
    cap_cells,
    held_code_resolution_c,
    mean_code_lsb_c,
    one_code_per_plateau,
    plateau_groups,
    quantised_channel,
)
from calibration.discrepancy.plateau_settling import settling_alike
from calibration.discrepancy.problem import (
    AxisBlockDesign,
    LinearProblem,
    axis_block_design,
    build_problem,
)
from calibration.discrepancy.protocol import Protocol, assess, visit_column
from calibration.discrepancy.protocol_order import time_and_position_confounded
from calibration.discrepancy.slot_settling import slot_settling_alike
from calibration.discrepancy.temperature_jump import temperature_jump_alike
from calibration.recording import Recording
from calibration.temperature_lsb import LSB_COLUMNS, declared_lsb_c

MAX_STAGES = 8
# The null of the families with columns and of the scan: sign flips of the recording's own
# residual, one per reading (stats.wild_replicates), not Gaussian replicates of the noise
# model (issue 22). The outlier family keeps its parametric null either way.
WILD_NULL = True
# With it, the noise the readings of one plateau share (a random offset per plateau and axis,
# a temperature error per plateau) is drawn into those replicates at the variance the
# stage's residual shows (plateau_noise.py; issue 22). Off: measured, not kept — it holds
# the level under injected per-plateau temperature errors but an effect confined to
# plateaus inflates its own variance estimate and is lost (second generator, attribution at
# 2x 63/120 -> 42/120; docs/diagnosis.md §2, docs/benchmarks.md).
PLATEAU_NULL = False
EXCESS_CHI2_RED = 2.0  # residual variance this far above sd²/n is a mismatch even if unnamed
BASE_MODEL = "sfem-cubic"

# A model term as findings link to it: (effect id, rows) — rows () for all but a
# per-reading term, which is one term per reading.
TermKey = tuple[str, tuple[int, ...]]


@dataclass
class Term:
    """One accepted model term: an effect at a fixed nonlinear parameter."""

    effect_id: str
    theta: float
    X: np.ndarray  # (m,k) unweighted columns in residual space
    rows: tuple[int, ...] = ()  # outlier rows
    theta_sd: float = float("nan")  # profile sd of a continuous theta (lag τ)

    @property
    def key(self) -> TermKey:
        """What a finding links to (:attr:`Finding.term_keys`): its effect id and rows."""
        return (self.effect_id, tuple(self.rows))


@dataclass
class Finding:
    effect: str
    axes: list[str]
    where: dict[str, Any]
    explanation: str
    parameters: dict[str, float]
    parameter_sd: dict[str, float]
    rmse_before_ug: float
    rmse_after_ug: float
    heldout_rmse_before_ug: float
    heldout_rmse_after_ug: float
    p_value: float
    test: str
    confusers: list[dict[str, Any]] = field(default_factory=list)
    theta: float = float("nan")
    rows: list[int] = field(default_factory=list)
    # The effect id of the model term(s) this finding reports; "" when nothing is modelled
    # (``unexplained``, one plateau's structure). With ``rows`` it is the finding's link to
    # its terms (:attr:`term_keys`): a finding re-labelled ``not_identifiable`` keeps it,
    # so every filter keeps or removes a finding and its term together. Not shown.
    term_effect: str = ""

    @property
    def term_keys(self) -> set[TermKey]:
        """The keys (:attr:`Term.key`) of the terms this finding reports (none if unmodelled)."""
        if not self.term_effect:
            return set()
        if self.rows:
            return {(self.term_effect, (int(r),)) for r in self.rows}
        return {(self.term_effect, ())}

    @property
    def named_as_modelled(self) -> bool:
        """Reported under its term's own effect name (not re-labelled not identifiable)."""
        return bool(self.term_effect) and self.effect == self.term_effect

    def to_json(self) -> dict[str, Any]:
        return {
            "effect": self.effect, "axes": self.axes, "where": self.where,
            "explanation": self.explanation, "parameters": self.parameters,
            "parameter_sd": self.parameter_sd,
            "rmse_before_ug": _r(self.rmse_before_ug), "rmse_after_ug": _r(self.rmse_after_ug),
            "heldout_rmse_before_ug": _r(self.heldout_rmse_before_ug),
            "heldout_rmse_after_ug": _r(self.heldout_rmse_after_ug),
            "evidence": {"test": self.test, "p_value": float(f"{self.p_value:.3g}")},
            "confusers": self.confusers,
        }


@dataclass
class Diagnosis:
    recording: str
    mode: str
    rmse_ug: float
    noise_ug: float
    noise_source: str
    findings: list[Finding]
    not_identifiable: list[dict[str, str]]
    located: dict[str, Any]
    heldout_scheme: str
    n_null: int
    alpha: float
    notes: list[str]
    final_rmse_ug: float
    residuals_before_ug: np.ndarray  # (N,3) or (N,1)
    residuals_after_ug: np.ndarray
    t_s: np.ndarray
    steps: np.ndarray
    positions: np.ndarray
    stage_log: list[dict[str, Any]] = field(default_factory=list)
    unexplained: dict[str, Any] = field(default_factory=dict)
    problem: LinearProblem | None = field(default=None, repr=False)  # for model extensions
    cannot_judge: str = ""  # why the recording is too small to test (then mismatch is None)
    protocol: dict[str, Any] = field(default_factory=dict)  # what it separates (protocol.py)
    # The final model's terms; each is reported by exactly one finding (Finding.term_keys).
    terms: list[Term] = field(default_factory=list, repr=False)

    @property
    def mismatch(self) -> bool | None:
        """A named finding, or residuals well above the recorded noise that nothing names;
        None when the recording is too small to judge."""
        if self.cannot_judge:
            return None
        return bool(self.findings)

    def to_dict(self) -> dict[str, Any]:
        return {
            "recording": self.recording,
            "baseline": {"model": BASE_MODEL, "rmse_ug": _r(self.rmse_ug),
                         "noise_ug": _r(self.noise_ug), "mode": self.mode,
                         "noise_source": self.noise_source},
            "mismatch": self.mismatch,
            "verdict": ("cannot judge" if self.cannot_judge else
                        "mismatch" if self.mismatch else "consistent"),
            **({"reason": self.cannot_judge} if self.cannot_judge else {}),
            "findings": [f.to_json() for f in self.findings],
            "not_identifiable": self.not_identifiable,
            **({"protocol": self.protocol} if self.protocol else {}),
            "final_rmse_ug": _r(self.final_rmse_ug),
            "heldout": self.heldout_scheme,
            "null": {"method": null_method(), "n_null": self.n_null,
                     "alpha": self.alpha},
            "unexplained": self.unexplained,
            "located": self.located,
            "notes": self.notes,
        }

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, ensure_ascii=False)

    def report(self) -> str:
        from calibration.discrepancy.report import text_report
        return text_report(self)


def _r(v: float) -> float | None:
    return float(round(float(v), 2)) if np.isfinite(v) else None


def heldout_improved(before_ug: float, after_ug: float) -> bool:
    """A term must lower the held-out RMS *as reported* (0.01 µg resolution, docs §6).

    Why: a gain below the reported resolution (≈ 0.1 % of a 10 µg noise floor) is no
    evidence that the term predicts unseen plateaus, and a finding whose reported
    held-out numbers tie contradicts its own claim. Such a term is rejected and the
    remaining candidates are tried.
    """
    return _r(after_ug) < _r(before_ug)


def null_method() -> str:
    """What the verdict's replicates are, as the JSON and the text report say it."""
    return ("sign flips of the residual, one per reading (families with columns, scan); "
            "parametric bootstrap (outliers)" if WILD_NULL
            else "parametric bootstrap of the fitted model")


# --- the pipeline ------------------------------------------------------------
def diagnose(recording: Recording, model: object | None = None, *, seed: int = 0,
             n_null: int = N_NULL, alpha: float = ALPHA,
             effects: tuple[CatalogueEffect, ...] = ALL_EFFECTS,
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Diagnose ``recording`` against the base model (docs/diagnosis.md).

    ``model`` (a ThermalModel) is accepted for the contract; the statistics
    always refit the base on the recording, because the effects must be tested
    after projecting out everything the base could absorb. ``progress``: called with one
    line at each step of the work (the base fit, each stage of the forward selection and
    its outcome, the checks, the final scan), for a caller that shows long work (the CLI
    on a long recording: ~8 min at 1 M readings).
    """
    say = progress if progress is not None else _silent
    notes: list[str] = []
    given_rmse = _given_model_rmse_ug(model, recording, notes)
    # Raw samples (many n = 1 rows per position): the samples of a capture share its
    # placement, vibration and temperature error, so they are not independent readings;
    # counted as such, a null twin was a "mismatch" (issue 10). Diagnose the capture means,
    # with σ = sd/√n plus the shared component estimated from the data (samples.py).
    # The LSB the recording declares for its temperature channel (temperature_lsb.py), read
    # before raw samples become capture means.
    lsb_c = (declared_lsb_c(recording, recording.temperature_source)
             if recording.has_temperature else None)
    # Not declared: capture means that are averages of the channel's codes show its LSB as
    # a lattice (plateau_noise.mean_code_lsb_c), as sure as a declared one (issue 22).
    if lsb_c is None and recording.has_temperature:
        lsb_c = mean_code_lsb_c(recording.columns[recording.temperature_source],
                                recording.columns.get("n"), recording.steps())
        lsb_from_means = lsb_c is not None
    else:
        lsb_from_means = False
    capture_means = samples_mod.is_raw_samples(recording)
    if capture_means:
        n_rows = len(recording)
        recording = samples_mod.position_means(recording)
        notes.append(f"raw samples: {n_rows} rows diagnosed as {len(recording)} capture means "
                     "(one per step and position); noise = sample sd/sqrt(n) plus the "
                     "between-capture sd estimated from the residuals")
    why_not = _too_few(recording)
    if why_not:
        return _cannot_judge(recording, why_not, n_null, alpha, notes)
    say(f"fitting the base model to {len(recording)} readings")
    pb = build_problem(recording, capture_means=capture_means)
    # A long recording cannot be short of dof: skip the rank's SVD (an (m × p) copy).
    p0 = pb.X0.shape[1]
    dof = pb.m - (p0 if pb.m > 20 * p0 else np.linalg.matrix_rank(pb.X0 * pb.w[:, None]))
    if dof < MIN_RESIDUAL_DOF:
        return _cannot_judge(recording, f"{len(recording)} reading(s) leave {dof} residual "
                             f"degree(s) of freedom after the base model (need at least "
                             f"{MIN_RESIDUAL_DOF})", n_null, alpha, notes)
    ctx = pb.ctx
    rng = np.random.default_rng(seed)
    # The verdict "mismatch" is the union of two tests, the forward selection's family test
    # and the localised scan, each calibrated by its own bootstrap: at α each, a null
    # recording is flagged with probability up to 2α (measured: 1.3 % at α = 1 %, issue 10).
    # Bonferroni over the two: each at α/2, so the verdict's false-alarm rate is ≤ α.
    alpha_sel = alpha_scan = alpha / 2
    fold_masks, scheme = folds(ctx, pb.degree)
    n_fit = max(MIN_N_NULL, min(n_null, int(NULL_BUDGET_BYTES // (8 * pb.m))))
    if n_fit < n_null:
        # Why: each replicate is a full residual vector (m entries), and the projections and
        # the per-reading statistics copy it a few times; 200 replicates were ~25 kB per row.
        # Fewer replicates coarsen the bootstrap p (the Bonferroni bound takes over below it).
        notes.append(f"n_null reduced from {n_null} to {n_fit} for memory "
                     f"({pb.m} residuals; budget {NULL_BUDGET_BYTES // 2**20} MiB per copy)")
        n_null = n_fit
    # Beyond the budget even at its floor (a long recording) the replicates are stored in
    # single precision (stats.replicate_dtype): half the largest array of the diagnosis.
    rep_dtype = stats.replicate_dtype(pb.m, n_null, NULL_BUDGET_BYTES)
    if rep_dtype != np.float64:
        notes.append(f"null replicates stored in single precision for memory ({pb.m} "
                     f"residuals × {n_null}; their statistics are formed in double)")
    if not pb.noise_from_sd:
        notes.append("no sd_* columns: noise estimated from the residuals (MAD)")
    if ctx.temperature_source == "none":
        notes.append("no temperature recorded: one plateau, base model has no temperature terms")
    if time_and_position_confounded(ctx.steps, ctx.positions, ctx.t_s):
        notes.append("the positions are visited in the same order on every plateau: time within "
                     "a plateau and orientation are one regressor here, so a warm-up or settling "
                     "and an orientation effect cannot be told apart (a seeded or balanced "
                     "order per plateau separates them: calibration/discrepancy/"
                     "protocol_order.py)")

    # Protocol-level identifiability first; the absorbed fraction is checked per stage.
    live: list[CatalogueEffect] = []
    not_ident: dict[str, dict[str, str]] = {}
    for eff in effects:
        ok, why, exp = eff.identifiable(ctx)
        if ok:
            live.append(eff)
        else:
            not_ident[eff.effect_id] = {"effect": eff.effect_id, "why": why, "experiment": exp}
    protocol = assess(ctx, visit_column(recording.columns),
                      {e.effect_id: e in live for e in effects})

    raw_cache: dict[tuple[str, float], np.ndarray] = {}

    def lifted(eff: CatalogueEffect, theta: float) -> np.ndarray:
        key = (eff.effect_id, theta)
        if key in raw_cache:
            return raw_cache[key]
        X = pb.lift(eff.regressors(ctx, theta))
        # Cached across stages only within a budget: every grid value of every effect is an
        # (m × k) array (~1 kB per reading in all), rebuilt cheaply on a long recording.
        if sum(a.nbytes for a in raw_cache.values()) + X.nbytes <= CACHE_BUDGET_BYTES:
            raw_cache[key] = X
        return X

    terms: list[Term] = []
    findings: list[Finding] = []
    rejected: set[str] = set()
    one_step: dict[str, dict[str, str]] = {}
    one_step_seen: list[one_step_report.OneStep] = []  # found, not named (one_step.py)
    unconfirmed: list[not_confirmed.NotConfirmed] = []  # found, held out did not confirm
    stage_log: list[dict[str, Any]] = []
    base_res = _residual(pb, [])
    prev_tests: dict[str, stats.CandidateTest] = {}
    unresolved: dict[str, list[str]] = {}  # named term → candidates it fits alike (by_fit)
    told_apart: set[str] = set()  # named over significant rivals by a clear margin (by_fit)
    why_alike: dict[str, str] = {}  # named term → why an unobservable confuser fits alike
    tail_nu = np.inf
    tail_shown = False  # the tail resolved at stats.TAIL_Z, not only at its point estimate
    groups = plateau_groups(pb) if WILD_NULL and PLATEAU_NULL else None
    # The sign flips' reading cap at each plateau's own scatter (stats.reading_cap, issue 22).
    cells = cap_cells(pb)
    channel = _quantised_channel(pb, notes, lsb_c, lsb_from_means) if WILD_NULL else None
    known = channel.known if channel is not None else None  # the scan's
    # The families: with the LSB declared (a channel the recording says is quantised
    # without dither), any rounding error within ±q/2 per plateau and value (the bound);
    # with q only read from the readings' grid, a draw per group at q²/12 in the
    # replicates, as the scan's. Measured on the second generator (docs/benchmarks.md): the
    # bound takes clean-channel nulls to 0.4 % with the LSB declared; without it they stay
    # at 1.5 % (the channel's alarms come from recordings that show no grid), while it
    # costs much power (right or not established 104 -> 78 of 120 at 2x).
    declared = channel is not None and channel.declared
    bounded = channel.bounded if declared else None
    wild_known = known if channel is not None and not declared else None
    # The scan, where the LSB is not declared and the channel's codes admit a coarser one
    # than its null draws (every code a whole degree): any rounding at that LSB is taken
    # out of each block's data score (within_rounding.py, issue 22).
    admitted = None if lsb_c is not None else within_rounding.admitted(pb)
    scan_box = within_rounding.coarser_box(admitted, channel.q_c if channel is not None
                                           else None)
    if scan_box is not None:
        notes.append(f"temperature channel ({ctx.temperature_source}): its codes admit an LSB "
                     f"of {2 * scan_box.half:g} °C, coarser than the null draws, which the "
                     "recording does not declare "
                     f"({LSB_COLUMNS.get(ctx.temperature_source, 'an _lsb_c column')}); the "
                     "localised scan takes each block's score net of any rounding error "
                     f"within ±{scan_box.half:g} °C per plateau and recorded value, and a "
                     "channel step within that rounding is not named")
    for _stage in range(MAX_STAGES):
        # The previous stage's (m × p) and (m × n_null) arrays go before the new ones are
        # built: two generations alive at once doubled the peak (issue 10, memory).
        U = E = None
        say(f"stage {_stage + 1}: testing the catalogue's effects against {n_null} null "
            "replicates")
        U, yw = _basis(pb, terms)
        e = yw - U @ (U.T @ yw)
        dof = np.sqrt(pb.m / max(pb.m - U.shape[1], 1))
        s = float(stats.robust_scale(e[:, None], dof)[0])
        E = stats.null_replicates(rng, pb.m, n_null, pb.row, pb.shared_t_loading, rep_dtype)
        stats.project_out_inplace(U, E)
        s_null = stats.robust_scale(E, dof)
        nu, nu_shown = _reading_dof(pb, U, e, s, terms)
        tail_nu = min(tail_nu, nu)
        tail_shown = tail_shown or bool(np.isfinite(nu_shown))
        # The outlier family against the Gaussian (or Student-t) replicates, the others
        # against sign flips of this residual, in the same buffer (stats.wild_replicates).
        rows = [f for f in live if f.per_reading]
        tests = _evaluate(pb, rows, rejected, terms, U, e, E, s, s_null, lifted, not_ident,
                          (nu, rng), bounded)
        shared = _shared(groups, e, U)
        if WILD_NULL:
            stats.wild_replicates(rng, e, U, pb.row, E,
                                  tuple(int(t.theta) for t in tests.values()), shared,
                                  wild_known, cells)
        tests.update(_evaluate(pb, [f for f in live if not f.per_reading], rejected, terms, U,
                               e, E, s, s_null, lifted, not_ident, (nu, rng), bounded))
        # The replicates are read: the term's checks below must not hold them too (issue 22,
        # memory: 480 MB at 1 M readings beside the one-plateau check's arrays).
        E = None
        tests = {f.effect_id: tests[f.effect_id] for f in live if f.effect_id in tests}
        if not tests:
            break
        # Each family's p calibrated on its own replicates before the minimum over families
        # (min-P, stats.min_p_family): the family whose nominal p is least calibrated no
        # longer sets every family's threshold. Ranked in log p: strong effects are far
        # beyond double precision in p (docs §5). Replicate b of the per-reading (outlier)
        # family is not the draw of replicate b of the others (its Gaussian or Student-t
        # draw was overwritten by the sign flips, stats.wild_replicates): within a replicate
        # its calibrated p and the others' are independent. On the recording they share one
        # residual and go together if at all (a reading far off raises the others' F too),
        # and the minimum of positively dependent p is stochastically larger than of
        # independent ones: the replicates' minimum is then at least as small as under the
        # joint law, and the test stays valid (conservative for that pair).
        listed = list(tests.values())
        p_family, i_best = stats.min_p_family(
            np.array([t.logp_adj for t in listed]),
            np.vstack([t.logp_adj_null for t in listed]))
        best = listed[i_best]
        stage_log.append({"best": best.effect_id, "p_family": p_family,
                          **({"plateau_theta": [float(f"{t:.3g}") for t in shared[1]]}
                             if shared is not None else {}),
                          "log10_p_adj": {k: float(t.logp_adj / np.log(10))
                                          for k, t in tests.items()}})
        for k in prev_tests:  # confuser p after the last accepted term
            if findings and k in tests:
                for c in findings[-1].confusers:
                    if c["effect"] == k:
                        c["p_after"] = float(f"{tests[k].p_adj:.3g}")
        if p_family > alpha_sel:
            say(f"stage {_stage + 1}: no further effect (best {best.effect_id}, "
                f"p_family {_p_text(p_family)} > {alpha_sel:.2g})")
            break
        say(f"stage {_stage + 1}: {best.effect_id} stands out (p_family {_p_text(p_family)}); "
            "checking it")
        # The name among confusers that explain the same structure: the clear best fit.
        best, close = by_fit.name_by_fit(best, tests, e, U.shape[1],
                                         partial(_explained, pb, U, e, lifted), alpha,
                                         ctx)
        eff = BY_ID[best.effect_id]
        X_refined = None
        if eff.continuous:
            best, X_refined = _refine(pb, eff, best, U, e)
        term = _make_term(pb, eff, best, lifted, X_refined)
        local = None if term.rows else _concentrated_on_one_step(pb, terms, term, alpha)
        if local is not None:
            rejected.add(eff.effect_id)
            stage_log[-1]["rejected_one_step"] = local
            notes.append(f"{eff.effect_id} not named: its evidence is step {local} alone, "
                         "which a local change of that plateau explains as well")
            # Seen but not separable here (issue 22): listed with the reason, not named (apart
            # from not_ident, which also says what the protocol could test).
            one_step.setdefault(eff.effect_id, {
                "effect": eff.effect_id,
                "why": (f"its evidence here is step {local} alone (p_family = "
                        f"{p_family:.2g}), which a local change of that plateau explains "
                        "as well"),
                "experiment": eff.experiment})
            one_step_seen.append(one_step_report.rejected(
                pb, eff.effect_id, term.X, _fit(pb, terms + [term])[0][-term.X.shape[1]:],
                local, p_family))
            continue
        excl_before = _flagged(pb, terms)
        excl_after = _flagged(pb, terms + [term])
        # Both sides are scored on the same rows (issue 10): a newly flagged reading leaves
        # the "before" figure too, else dropping it alone counts as the term's gain (the
        # circular 44.02 → 40.03 µg of the issue). Its gain is then only its influence on
        # the predictions of the other plateaus.
        ho_before = _heldout_ug(pb, terms, fold_masks, excl_after)
        ho_after = _heldout_ug(pb, terms + [term], fold_masks, excl_after)
        # A flagged reading is evidenced by its own test, which is a held-out test already:
        # the reading left out and predicted by all the others. Scored on the same rows, its
        # gain on the other plateaus is only its pull on their fit, far below their noise,
        # so "not worse" there was a coin toss (issue 22: half the outliers at twice their
        # detectable size were rejected by it). Its held-out figures are reported, not
        # required. Every other term must improve them.
        ok = bool(term.rows) or heldout_improved(ho_before, ho_after)
        in_noise: tuple[float, float] | None = None
        if eff.shrunk_heldout:
            # A term spread thinly over many places (a turn per table pose) is judged in the
            # noise's units, as its test is: in µg the noisiest plateaus' own scatter decides
            # (issue 22: a turn at p = 1e-7 "worsened" a 50 µg held-out RMS by 0.07 µg).
            in_noise = _heldout_in_noise_units(pb, terms, term, fold_masks, excl_after)
            ok = in_noise[1] < in_noise[0]
        # The model with the term, fitted once: the records and the finding below read it.
        fitted = _fit(pb, terms + [term])[:2]
        if not ok:
            rejected.add(eff.effect_id)
            stage_log[-1]["rejected_heldout"] = [ho_before, ho_after]
            unconfirmed.append(replace(
                _not_confirmed(pb, eff, term, terms, p_family, ho_before, ho_after, fitted),
                heldout_noise_units=in_noise))
            continue
        # A term whose fit, beyond the base model, an earlier term almost wholly carries
        # cannot be told from it: fitted together the two cancel (issue 22: an ADC band
        # error read as a cube of each input "K3 = −364,500 µg/g³" beside a turn of each
        # table pose of 11,420 µrad). Not added; reported with the reason.
        share, most = _outside_earlier_terms(
            pb, terms, term, _term_coefficients(pb, terms + [term], term, fitted)[0])
        if share < MIN_SHARE_OUTSIDE_TERMS:
            rejected.add(eff.effect_id)
            stage_log[-1]["rejected_within"] = [most, share]
            unconfirmed.append(replace(
                _not_confirmed(pb, eff, term, terms, p_family, ho_before, ho_after, fitted),
                within=most, share_outside=share))
            continue
        res_before = _residual(pb, terms)
        terms.append(term)
        res_after = _residual(pb, terms)
        findings.append(_finding(pb, eff, best, term, terms, tests, p_family,
                                 _rms(res_before, excl_before), _rms(res_after, excl_after),
                                 ho_before, ho_after, fitted, alpha=alpha))
        if close:
            unresolved[eff.effect_id] = close
        elif by_fit.rivals(best, tests, alpha):
            told_apart.add(eff.effect_id)
        alike, why_alike[eff.effect_id] = eff.not_told_from(pb, U, e, term.X, term.theta,
                                                               alpha)
        if alike:  # a confuser with no regressor explains it as well (effects/base.py)
            unresolved[eff.effect_id] = list(dict.fromkeys(
                (close or [eff.effect_id]) + alike))
            told_apart.discard(eff.effect_id)
        prev_tests = tests
    U = E = None  # the last stage's basis and replicates: the scan builds its own
    if np.isfinite(tail_nu) and tail_shown:
        notes.append(f"the readings are heavier-tailed than Gaussian (Student-t, nu = "
                     f"{tail_nu:.1f}, from their own scatter): the null draws them so")
    elif np.isfinite(tail_nu):
        # Said as what it is: the point estimate the outlier null uses, not a finding
        # about the noise (on a few hundred readings it is not told from a Gaussian).
        notes.append(f"the outlier test's null draws the readings with a Student-t tail at "
                     f"its point estimate from their own scatter (nu = {tail_nu:.1f}); on "
                     f"these readings that tail is not told from a Gaussian one")
    # Physics checks (issue 10, docs/diagnosis.md §7): a named term must have its physics'
    # shape (CatalogueEffect.misses: an outlier is isolated, a function of the specific force
    # is the same at every visit of a direction). One that is not is withdrawn, and the
    # structure it was fitted to is reported as ``unexplained`` where it is.
    say(f"physics checks of {len(findings)} finding(s)")
    terms, findings, not_named = _physics_checks(pb, terms, findings, alpha, notes)
    findings = [_turned_or_bent(pb, terms, f, alpha, not_ident, notes) for f in findings]
    terms, findings, after_turn = _shape_after_turn(pb, terms, findings, alpha, notes)
    not_named += after_turn
    if lsb_c is None:  # a declared LSB's box is in every family's test already
        terms, findings = _within_channel_rounding(pb, terms, findings, alpha_sel, admitted,
                                                   not_ident, notes)
    say("localised scan of the final residual")
    scanned = _scan_final(pb, terms, rng, n_null, alpha_scan, known, scan_box)
    if scanned.significant:
        # Confuser check (issue 10): an outlier is "isolated in time". A flagged reading
        # inside a step or position where the scan still finds structure is part of that
        # structure, not an outlier: its term is withdrawn and the place is reported.
        inside = _rows_in_places(pb, scanned.places)
        withdrawn = {t.key for t in terms if t.rows and inside[list(t.rows)].any()}
        if withdrawn:
            terms, findings, gone = withdraw(terms, findings, withdrawn)
            notes.append(f"reading(s) {sorted(r for k in gone for r in k[1])} not named "
                         "outlier: they lie where the local scan finds structure beyond them "
                         "(not isolated)")
            scanned = _scan_final(pb, terms, rng, n_null, alpha_scan, known, scan_box)
    left_structure: list[str] = []  # effects fitted here whose terms left their places
    if scanned.significant:
        # "A named finding must explain most of the located structure" (issue 10): when
        # structure remains exactly where a named term acts (its own steps or positions,
        # not all of them), the term took a share of something it does not describe
        # (orientation history named a nonlinearity under the fixed Table 1 order).
        # By the findings' links to their terms, not their names: a finding already
        # re-labelled ``not_identifiable`` (a turn of the reference) goes with its term.
        demoted = _leaves_its_own_places(pb, findings, scanned.places)
        if demoted:
            terms, findings, gone = withdraw(terms, findings, demoted)
            left_structure = sorted({k[0] for k in gone})
            notes.append(f"{', '.join(left_structure)} not named or modelled: "
                         "after it, structure remains at the steps/positions where it acts, "
                         "so it does not explain the located structure")
            scanned = _scan_final(pb, terms, rng, n_null, alpha_scan, known, scan_box)
    # A finding's numbers were fitted at its stage, in the model of that moment; a term
    # withdrawn since (a turn of the table beside a bend, say) may have shared its columns,
    # and the stale coefficients then cancel across the two (K3 = −3·10⁵ µg/g³ "± 49").
    # The named findings are stated in the model that is kept.
    findings = _restated(pb, terms, findings, alpha)
    # What the protocol separates: the effects still testable after the absorbed fractions.
    protocol = protocol.with_testable({e.effect_id: e.effect_id not in not_ident
                                       for e in effects})
    # A name the data chose over its significant rivals by a clear margin (by_fit) stands
    # even where the protocol alone would withhold it: the fit, not the protocol, told them.
    # Both apply to a finding still named as its term (one re-labelled already is not named).
    findings = [f if not f.named_as_modelled or f.term_effect in told_apart
                else _as_protocol_allows(f, protocol, not_ident, alpha) for f in findings]
    findings = [by_fit.as_not_separable(f, unresolved[f.term_effect], not_ident,
                                        why_alike.get(f.term_effect, ""))
                if f.named_as_modelled and f.term_effect in unresolved else f
                for f in findings]
    # A rate term whose gains are a lag's (locked to ∂output/∂T) is not named (issue 22);
    # here, after the demotions above (its term stays in the model either way).
    findings = [lag_alike(pb, terms, f, alpha, not_ident, notes, _design) for f in findings]
    # A per-plateau offset of the thermal/time family that a jump of the output at a
    # temperature fits as well is not named (temperature_jump.py, issue 22: a bias jump at
    # a die temperature was named a power cycle on one-way staircases, a rectified
    # vibration where the compressor runs on the cold plateaus only).
    findings = [temperature_jump_alike(pb, terms, f, alpha, not_ident, notes, _design)
                for f in findings]
    # A rate or lag term that a settling after each plateau's start, the same on every
    # plateau, fits as well is not named (plateau_settling.py, issue 22: a fixture relaxing
    # after the moves of each plateau was named a temperature rate).
    findings = [settling_alike(pb, terms, f, alpha, not_ident, notes, _design)
                for f in findings]
    # A function of the specific force that a settling at each slot of the visiting order
    # fits as well is not named (slot_settling.py, issue 22: when the order repeats on every
    # plateau the slots span every function of the position, as for turntable_geometry).
    findings = [slot_settling_alike(pb, terms, f, alpha, not_ident, notes, _design)
                for f in findings]
    # A flagged reading whose recorded temperature jumped off its neighbours and whose
    # residual is the model's own ∂output/∂T is a glitch of the channel, not an outlier;
    # where the data cannot tell, not separable (channel_glitch.py, issue 22).
    findings = _channel_glitches(pb, terms, findings, alpha, not_ident)
    # Once more, after the two demotions above added to not_ident: candidates the fit
    # could not tell apart are not "separable" in this recording, and the protocol block
    # must not say so beside a finding that says the opposite.
    protocol = protocol.with_testable({e.effect_id: e.effect_id not in not_ident
                                       for e in effects})
    findings = _merge_outliers(findings)
    final_res = _residual(pb, terms)
    flagged = _flagged(pb, terms)
    n = ctx.n
    shape = (n, 3) if pb.mode == "reference" else (n, 1)
    noise = float(np.sqrt(np.mean((1.0 / pb.w) ** 2)) * 1e6)
    if not pb.noise_from_sd:
        noise = float(stats.robust_scale((base_res * pb.w)[:, None], 1.0)[0]
                      * np.sqrt(np.mean((1.0 / pb.w) ** 2)) * 1e6)
    unexplained = _excess_test(pb, final_res, flagged, terms, alpha)
    unexplained = {**scanned.to_dict(), "chi_square": unexplained}
    if scanned.significant or not_named:
        findings.append(_unexplained_finding(pb, scanned, final_res, not_named,
                                             left_structure if scanned.significant else []))
    # Found by the family test, withheld as one plateau's: reported, not dropped (issue 22).
    # One still_seen for both reports: it builds the final model's basis once, when asked.
    if lsb_c is None and one_step_seen:  # a channel step withheld as one plateau's, too
        kept = _within_channel_rounding_one_step(pb, terms, one_step_seen, alpha_sel,
                                                 admitted, not_ident, notes)
        if len(kept) < len(one_step_seen):
            one_step_seen = kept
            protocol = protocol.with_testable({e.effect_id: e.effect_id not in not_ident
                                               for e in effects})
    seen = one_step_report.still_seen(pb, _basis, terms, alpha)
    final_rms = _rms(final_res, flagged)
    findings, shown = one_step_report.report(pb, findings, one_step_seen, Finding, seen,
                                             final_rms)
    # Found by the family test, not confirmed on held-out data: reported (not_confirmed.py).
    findings = not_confirmed.report(findings, unconfirmed, Finding, seen, final_rms)
    # An effect the base absorbs (not tested) whose remnant is a not-identifiable finding's
    # structure is among that finding's candidates too (absorbed_alike.py, issue 22).
    findings = absorbed_alike.extend(
        pb, findings, partial(_columns_of, terms, one_step_seen), not_ident, lifted,
        partial(_basis, pb, []))
    if shown:  # the protocol block must not call them separable beside that finding
        for k in shown:
            not_ident.setdefault(k, one_step[k])
        protocol = protocol.with_testable({e.effect_id: e.effect_id not in not_ident
                                           for e in effects})
    base_rmse = _rms(base_res, np.zeros(n, bool)) if given_rmse is None else given_rmse
    located = locate_residuals(pb, base_res, final_res, flagged)
    box = bounded if bounded is not None else scan_box
    if not findings and unexplained["chi_square"].get("significant"):
        # Never "consistent" beside a residual far above the noise (issue 22: seven captures
        # 13x the noise on 90 readings drew the outlier null's tail from themselves, and the
        # verdict said consistent at chi2/dof 7.7, p 1e-226) — unless the channel's possible
        # rounding, which the tests already allow, makes the excess.
        if box is not None and _excess_within_rounding(pb, final_res, flagged, box, terms,
                                                       alpha):
            notes.append(
                f"the final residual is {unexplained['chi_square']['rms_over_noise']:.2f} × "
                "the recorded noise, within what the temperature channel's possible rounding "
                f"(±{box.half:g} °C per plateau) makes through the base model's ∂output/∂T: "
                "not called a mismatch; declare the channel's LSB to test it")
        else:
            findings = [_excess_finding(pb, unexplained["chi_square"], located, final_res)]
    say(f"done: {len(findings)} finding(s)")
    return Diagnosis(
        unexplained=unexplained,
        recording=str(recording.path), mode=pb.mode,
        rmse_ug=base_rmse, noise_ug=noise,
        noise_source=("sd/sqrt(n) scaled to the scatter within plateaus (kappa, tau, "
                      "per plateau)" if pb.noise_within_plateaus else
                      "sd/sqrt(n) + between-capture sd (residual MAD)"
                      if pb.between_sd_g is not None else
                      "sd/sqrt(n)" if pb.noise_from_sd else "residual MAD"),
        findings=findings, not_identifiable=list(not_ident.values()) + [
            v for k, v in one_step.items() if k not in not_ident],
        located=located, heldout_scheme=scheme,
        n_null=n_null, alpha=alpha, notes=notes, final_rmse_ug=_rms(final_res, flagged),
        residuals_before_ug=(base_res * 1e6).reshape(shape),
        residuals_after_ug=(final_res * 1e6).reshape(shape),
        t_s=ctx.t_s, steps=ctx.steps, positions=ctx.positions, stage_log=stage_log, problem=pb,
        protocol=protocol.to_json(), terms=terms,
    )


def _silent(_line: str) -> None:
    """No progress shown (the library default)."""


def _p_text(p: float) -> str:
    """"= 0.013" or "< 1e-300" (a p beyond double precision)."""
    return f"= {p:.2g}" if p >= 1e-300 else "< 1e-300"


MIN_RESIDUAL_DOF = 10
# Below this share of its fit outside the earlier terms (beyond the base model) a term is
# not added: ≥ 90 % of it is an earlier term's, and fitted together their coefficients
# cancel. On the second generator's catalogue effects at 2× (480 cases, two seeds) no
# accepted term came below 0.2; a bend beside a turn of each pose came at 0–0.05.
MIN_SHARE_OUTSIDE_TERMS = 0.1
NULL_BUDGET_BYTES = 64 * 2**20  # one copy of the null replicates (m × n_null float64)
MIN_N_NULL = 20
CACHE_BUDGET_BYTES = 64 * 2**20  # candidate regressors kept between stages
MIN_ROWS = 6  # below this even one temperature's 12 SFEM parameters leave < 6 dof


def _too_few(rec: Recording) -> str:
    if len(rec) < MIN_ROWS:
        return (f"{len(rec)} reading(s): too few to judge a mismatch (need at least "
                f"{MIN_ROWS} readings, and {MIN_RESIDUAL_DOF} residual degrees of freedom "
                "after the base model)")
    return ""


def _cannot_judge(rec: Recording, why: str, n_null: int, alpha: float,
                  notes: list[str]) -> Diagnosis:
    """A recording too small to test: say so instead of ``mismatch: false`` (issue 10)."""
    n = len(rec)
    empty = np.zeros((n, 3))
    steps = rec.steps() if n else np.zeros(0, int)
    return Diagnosis(
        recording=str(rec.path), mode="reference" if rec.has_reference else "norm",
        rmse_ug=float("nan"), noise_ug=float("nan"), noise_source="not estimated",
        findings=[], not_identifiable=[], located={}, heldout_scheme="none",
        n_null=n_null, alpha=alpha, notes=notes, final_rmse_ug=float("nan"),
        residuals_before_ug=empty, residuals_after_ug=empty, t_s=rec.t_s, steps=steps,
        positions=np.zeros(n, int), cannot_judge=why)


def _given_model_rmse_ug(model: object | None, rec: Recording, notes: list[str]) -> float | None:
    """Residual RMS of a given model on this recording (the baseline the user asked about).

    The statistics still refit the base: effects must be tested after projecting
    out everything the base model could absorb, whatever model was given.
    """
    if model is None or not hasattr(model, "compensate"):
        return None
    T = rec.temperature_c() if rec.has_temperature else np.full(len(rec), np.nan)
    try:
        cal = model.compensate(rec.raw_g, T, extrapolate=True)  # type: ignore[attr-defined]
    except TypeError:
        cal = model.compensate(rec.raw_g, T)  # type: ignore[attr-defined]
    ref = rec.ref_g
    res = cal - ref if ref is not None else np.linalg.norm(cal, axis=1) - 1.0
    notes.append("baseline RMS is the given model's; the tests refit the base model so that "
                 "effects are tested after projecting out all it can absorb")
    return float(np.sqrt(np.mean(res**2)) * 1e6)


def _concentrated_on_one_step(pb: LinearProblem, terms: list[Term], term: Term,
                              alpha: float) -> int | None:
    """Confuser check against a local anomaly (issue 10): the step whose removal kills it.

    Each plateau in turn gets a free local SFEM block (per axis 1, a_x, a_y, a_z on that
    step: "this plateau differs"); if the term is then no longer significant at α (single
    test, lenient to the term), its evidence is that plateau alone — a rate slope on the
    first plateau is then a warm-up or a session start as much as a rate effect — and the
    name is not given. Returns the step.
    """
    ctx = pb.ctx
    eff = BY_ID[term.effect_id]
    if eff.named_by_fit:
        # The thermal/time family: by fit against a change of each plateau alone, the
        # question by_fit answers for its rivals (one_step_fit.py, issue 22).
        decided, step = one_plateau_fits_as_well(pb, terms, term, eff.one_sided, _design,
                                                 partial(_shape_at, pb, eff))
        if decided:
            return step
    beta = _fit(pb, terms + [term])[0]
    contrib = term.X @ beta[-term.X.shape[1]:]
    per_step = {int(s_): float(np.sum((contrib * pb.w)[ctx.steps[pb.row] == s_] ** 2))
                for s_ in ctx.step_ids}
    if len(per_step) < 3:
        return None
    Tw = pb.whiten(term.X)
    # Every plateau in turn, the largest contributions first: a jump "from step 1 on" is
    # as well "step 0 differs" (its complement), which carries none of the contribution.
    for step in sorted(per_step, key=per_step.get, reverse=True):
        # The model and the plateau's block, as a basis held as its recipe on a long
        # recording (issue 22: the whole design, its copy with the block and their basis
        # were 2.5 GB at 300 k readings).
        U, yw = _basis(pb, terms + [Term("one_step", float(step), _one_step_block(pb, step))])
        e = yw - U @ (U.T @ yw)
        with np.errstate(divide="ignore", invalid="ignore"):
            lp, _, k, absorbed, _ = stats.linear_stats(U, Tw, e, np.zeros((pb.m, 1)))
        # Not the absorbed fraction in general: a nuisance column confined to the step (the
        # lag's first-plateau start) is absorbed whole and would dominate it; k and p decide.
        # A one-column term is judged by its own limit too (a channel step from plateau 1
        # is "plateau 0 differs" up to its linearisation error, issue 22).
        gone = Tw.shape[1] == 1 and absorbed > BY_ID[term.effect_id].absorbed_max
        if k == 0 or lp > np.log(alpha) or gone:
            return step
    return None


def _shape_at(pb: LinearProblem, eff: CatalogueEffect, step: int) -> np.ndarray | None:
    """``eff``'s lifted columns with plateau ``step`` on, for an effect profiled over the
    plateaus (a jump from step k on, a channel step); None for any other (one_step_fit)."""
    grid = eff.grid(pb.ctx)
    plateaus = {float(s) for s in pb.ctx.step_ids}
    if not grid or not set(grid) <= plateaus:
        return None
    return pb.lift(eff.regressors(pb.ctx, float(step)))


def _one_step_block(pb: LinearProblem, step: int) -> np.ndarray | AxisBlockDesign:
    """"Plateau ``step`` differs", lifted (m × 12): per axis 1, a_x, a_y, a_z on its readings.

    In reference mode these are the axis blocks of an (N × 4) block (problem.AxisBlockDesign
    above the size: not an (m × 12) array that is zero off the plateau)."""
    if pb.mode == "reference":
        return axis_block_design(plateau_inputs(pb.ctx, step))
    return pb.lift(sfem_block(pb.ctx, step))


def _scan_final(pb: LinearProblem, terms: list[Term], rng: np.random.Generator, n_null: int,
                alpha: float, known: tuple[stats.SharedGroups, np.ndarray] | None,
                bounded: stats.BoundedShared | None = None) -> scan_mod.ScanResult:
    """The localised scan (scan.py) on the residual of the final model; ``known``, the
    quantised channel's shared noise (:func:`_quantised_channel`), read once per diagnosis;
    ``bounded``, the rounding at a coarser LSB the codes admit (within_rounding.coarser_box)."""
    U, yw = _basis(pb, terms)  # the replicates below are the largest array
    e = yw - U @ (U.T @ yw)
    dtype = stats.replicate_dtype(pb.m, n_null, NULL_BUDGET_BYTES)
    if WILD_NULL:  # sign flips of this residual (stats.wild_replicates)
        groups = plateau_groups(pb) if PLATEAU_NULL else None
        E = stats.wild_replicates(rng, e, U, pb.row, np.empty((pb.m, n_null), dtype),
                                  shared=_shared(groups, e, U), known=known,
                                  plateaus=cap_cells(pb))
    else:
        E = stats.null_replicates(rng, pb.m, n_null, pb.row, pb.shared_t_loading, dtype)
        stats.project_out_inplace(U, E)
    return scan_mod.scan(pb, U, e, E, alpha, bounded)


def _quantised_channel(pb: LinearProblem, notes: list[str], declared_q_c: float | None,
                       from_means: bool = False) -> QuantisedChannel | None:
    """The rounding error of a non-dithering quantised temperature channel
    (plateau_noise.quantised_channel), said in ``notes``; or None. ``declared_q_c``: the LSB
    the recording declares (temperature_lsb.py), or, ``from_means``, the one its capture
    means show (plateau_noise.mean_code_lsb_c), taken as declared."""
    found = quantised_channel(pb, declared_q_c, by_plateau=from_means)
    ctx = pb.ctx
    if found is None:
        if ctx.temperature_source != "none" and one_code_per_plateau(ctx.temp_c, ctx.steps) \
                and held_code_resolution_c(ctx.temp_c, ctx.steps) is None:
            notes.append(f"temperature channel ({ctx.temperature_source}) holds one value "
                         "through each plateau: quantised without dither, at an LSB the "
                         "recording does not show (no plateau moves by one code) nor declare "
                         f"({LSB_COLUMNS.get(ctx.temperature_source, 'an _lsb_c column')}), "
                         "and its codes, whole degrees, bound nothing (a die settled on "
                         "setpoints writes them whatever the LSB); "
                         "each plateau's temperature may be off by up to half that LSB, which "
                         "the families' null does not include (a rate or hysteresis of that "
                         "size is not told from it; a channel step within it is not named)")
        return None
    how = ("read from its capture means, averages of its codes on a lattice of LSB/n (not "
           f"declared: {LSB_COLUMNS.get(ctx.temperature_source, 'an _lsb_c column')})"
           if from_means else "declared by the recording" if found.declared else
           f"without dither ({100 * found.fraction:.0f} % of the readings on its codes)")
    if found.lower_bound:
        notes.append(f"temperature channel ({ctx.temperature_source}) holds one value "
                     "through each plateau: quantised without dither, at an LSB the "
                     "recording does not show (no plateau moves by one code) nor declare "
                     f"({LSB_COLUMNS.get(ctx.temperature_source, 'an _lsb_c column')}); its "
                     f"codes are written to {found.q_c:.4g} °C, so each plateau's temperature "
                     f"is known to ±{found.q_c / 2:.3g} °C at best; the null includes that "
                     "least error as a draw per plateau and code at its variance q²/12 (a "
                     "coarser LSB, or a channel step, rate or hysteresis the rounding makes "
                     "beyond it, is not included: declare the LSB)")
    elif found.declared:
        notes.append(f"temperature channel ({ctx.temperature_source}) quantised at "
                     f"{found.q_c:.4g} °C {how}: the readings of a plateau on one code share "
                     f"its temperature, known to ±{found.q_c / 2:.3g} °C; the tests allow any "
                     "such error through the base model's ∂output/∂T (an effect no larger "
                     "than such errors can make — a channel step, rate or hysteresis of that "
                     "size, a drift or a nonlinearity they mimic — is not established)")
    else:
        notes.append(f"temperature channel ({ctx.temperature_source}) quantised at "
                     f"{found.q_c:.4g} °C {how}: the readings of a plateau on one code share "
                     f"its temperature, known to ±{found.q_c / 2:.3g} °C; the null includes "
                     f"that error as a draw per plateau and code at its variance q²/12 (a "
                     f"channel that does not dither: declare its LSB, "
                     f"{LSB_COLUMNS.get(ctx.temperature_source, 'an _lsb_c column')}, and "
                     "the tests allow any error within ±q/2 instead)")
    return found


def _shared(groups: stats.SharedGroups | None, e: np.ndarray, U: np.ndarray
            ) -> tuple[stats.SharedGroups, np.ndarray, float] | None:
    """The plateau-shared noise of this residual (stats.shared_variance), or None."""
    if groups is None:
        return None
    theta, s2 = stats.shared_variance(e, U, groups)
    return (groups, theta, s2) if np.any(theta > 0) else None


def _reading_dof(pb: LinearProblem, U: np.ndarray, e: np.ndarray, s: float,
                 terms: list[Term]) -> tuple[float, float]:
    """ν of the per-reading Student-t tail this residual shows (∞: Gaussian), for the null
    (at its point estimate, stats.NULL_TAIL_Z), and the same ν where the tail is resolved at
    stats.TAIL_Z standard errors (∞ where it is not: what the notes may call heavier-tailed).

    Why: the readings of a real recording (capture means under unrectified vibration,
    settling, re-seating) are heavier-tailed than Gaussian, and the outlier test's max over
    readings against a Gaussian null named the largest of them an outlier (2 % of nulls on
    the second generator). The tail is read from the residual's entries (stats.
    entry_tail_dof) of the readings not yet excluded and not among the largest
    (_tail_entries), so an outlier does not make its own null heavier.
    """
    skip = {r for t in terms for r in t.rows}
    t_row, _, _ = stats.row_stats(U, e, np.zeros((pb.m, 1)), pb.row, pb.ctx.n, s, np.ones(1),
                                  skip, pb.shared_t_loading)
    keep = np.array([i not in skip for i in range(pb.ctx.n)]) & (t_row > 0)
    z = _tail_entries(pb, U, e, s, t_row, keep)
    return stats.entry_tail_dof(z, stats.NULL_TAIL_Z), stats.entry_tail_dof(z)


def _tail_entries(pb: LinearProblem, U: np.ndarray, e: np.ndarray, s: float,
                  t_row: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The entries the outlier null's ν is read from (stats.entry_tail_dof): those of the
    readings in ``keep`` other than the stats.TAIL_OUTLIERS largest (the test's candidates),
    in the model refitted without the candidates (stats.leave_entries_out), each over its
    residual's standard deviation s·√(1 − h).

    Why (issue 22): a capture mean's error heavy-tailed on each axis (the third generator's
    Student-t means) shows in the per-reading statistic only where one axis dominates it:
    its 95th percentile stays near χ²_g's and the tail shows only in the top few readings,
    so the null was Gaussian where the recording's own entries are not. The candidates are
    left out of the fit as well as of the entries: a reading far off pulls the fit, and on
    few readings per column its pull moves its plateau's and position's other readings by
    a share of its size — those entries made the tail heavy (ν at its floor), and one
    reading 3.8 mg off against 122 µg noise on 48 readings was not an outlier by it. Three
    candidates, not two: with a third outlier's entries among the others the tail was read
    from that outlier (three readings 1.6–2.3 mg off on 90 readings: ν 5 in place of ∞).
    """
    cand = np.flatnonzero(keep)
    cand = cand[np.argsort(t_row[cand])[::-1][:stats.TAIL_OUTLIERS]]
    use = keep.copy()
    use[cand] = False
    h = stats.leverage(U)  # by row blocks: no (m × p) temporary, no dense basis
    e, h = stats.leave_entries_out(U, e, h, np.flatnonzero(np.isin(pb.row, cand)))
    z = e / (s * np.sqrt(np.maximum(1.0 - h, 1e-12)))
    return z[use[pb.row] & (h < 1.0 - 1e-6)]


def _leaves_its_own_places(pb: LinearProblem, findings: list[Finding],
                           places: list[dict[str, Any]]) -> set[TermKey]:
    """The terms (keys) of findings with a scan place at their own steps or positions.

    Only a modelled finding (named or re-labelled ``not_identifiable``) that acts at some,
    not all, steps or positions; per-reading terms are judged by the outlier check above.
    """
    ctx = pb.ctx
    n_steps, n_pos = len(ctx.step_ids), len(np.unique(ctx.positions))
    out: set[TermKey] = set()
    for f in findings:
        if f.rows or not f.term_keys:
            continue
        steps, pos = set(f.where.get("steps") or []), set(f.where.get("positions") or [])
        for p in places:
            if ("step" in p and p["step"] in steps and len(steps) < n_steps) or (
                    "position" in p and p["position"] in pos and len(pos) < n_pos):
                out |= f.term_keys
    return out


def withdraw(terms: list[Term], findings: list[Finding], keys: set[TermKey]
             ) -> tuple[list[Term], list[Finding], set[TermKey]]:
    """Remove the terms ``keys`` and the findings that report them, always together.

    A finding reporting several terms (merged readings) takes all of them along, so no term
    is left in the model without the finding that says so. Returns the kept terms and
    findings and the keys removed.
    """
    gone = set(keys)
    for f in findings:
        if f.term_keys & gone:
            gone |= f.term_keys
    return ([t for t in terms if t.key not in gone],
            [f for f in findings if not f.term_keys & gone], gone)


def _finding_of(findings: list[Finding], term: Term) -> Finding:
    """The finding that reports ``term`` (by its link, whatever its label)."""
    return next(f for f in findings if term.key in f.term_keys)


def _rows_in_places(pb: LinearProblem, places: list[dict[str, Any]]) -> np.ndarray:
    ctx = pb.ctx
    inside = np.zeros(ctx.n, bool)
    for p in places:
        if "step" in p:
            inside |= ctx.steps == p["step"]
        if "position" in p:
            inside |= ctx.positions == p["position"]
    return inside


def _physics_checks(pb: LinearProblem, terms: list[Term], findings: list[Finding],
                    alpha: float, notes: list[str]
                    ) -> tuple[list[Term], list[Finding], list[dict[str, Any]]]:
    """Withdraw the terms whose module finds structure its physics cannot make (issue 10).

    Outlier terms are judged against the model without any flagged reading's term (their
    deviation must not be what the other readings predict); every other term against the
    whole model. Returns the kept terms and findings and, per withdrawn term, where the
    structure is (``CatalogueEffect.misses``) with the term's family p.
    """
    not_named: list[dict[str, Any]] = []
    gone: set[TermKey] = set()
    for row_terms in (True, False):
        chosen = [t for t in terms if bool(t.rows) == row_terms]
        if not chosen:
            continue
        U, yw = _basis(pb, [t for t in terms if not t.rows] if row_terms else terms)
        e = yw - U @ (U.T @ yw)
        for t in chosen:
            f = _finding_of(findings, t)
            miss = BY_ID[t.effect_id].misses(pb, U, e, t.theta, f.where, f.axes, alpha)
            if miss is not None:
                not_named.append({"effect": t.effect_id, **miss, "p_value": f.p_value,
                                  "test": f.test})
                gone.add(t.key)
        U = e = None
    runs = _inside_withdrawn_runs(pb, terms, findings, not_named)
    gone |= {(n["effect"], (int(n["row"]),)) for n in runs}
    not_named += runs
    if not_named:
        terms, findings, _ = withdraw(terms, findings, gone)
        _note_not_named(not_named, notes)
    return terms, findings, not_named


def _note_not_named(not_named: list[dict[str, Any]], notes: list[str]) -> None:
    """A note per withdrawn term: where, and why its physics does not fit there."""
    for n in not_named:
        at = (f"reading {n['row']}" if "row" in n else
              "step(s) " + ", ".join(str(s) for s in n["steps"]) if n.get("kind") == "time"
              else "position(s) " + ", ".join(str(p) for p in n["positions"]))
        notes.append(f"{n['effect']} not named at {at}: {n['why']}")


def _within_channel_rounding(pb: LinearProblem, terms: list[Term], findings: list[Finding],
                             level: float, admitted: within_rounding.Admitted | None,
                             not_ident: dict[str, dict[str, str]],
                             notes: list[str]) -> tuple[list[Term], list[Finding]]:
    """Withdraw a channel finding whose evidence the rounding at the coarsest LSB the
    channel's codes admit can make (within_rounding.py, issue 22), and report it as not
    established with the reason (``not_ident``, ``notes``): the recording cannot separate it
    from the rounding unless it declares the LSB."""
    found = within_rounding.within(pb, terms, level, _basis, admitted)
    if not found:
        return terms, findings
    _say_within_rounding(pb, found, not_ident, notes)
    terms, findings, _ = withdraw(terms, findings, {w.key for w in found})
    return terms, findings


def _within_channel_rounding_one_step(pb: LinearProblem, terms: list[Term],
                                      records: list[one_step_report.OneStep], level: float,
                                      admitted: within_rounding.Admitted | None,
                                      not_ident: dict[str, dict[str, str]], notes: list[str]
                                      ) -> list[one_step_report.OneStep]:
    """The one-plateau records (one_step.py) kept: a channel step withheld as one plateau's
    whose evidence the admitted rounding can make is reported as that, not as a one-plateau
    change (:func:`_within_channel_rounding`)."""
    found = within_rounding.within(pb, terms, level, _basis, admitted, one_step=records)
    if not found:
        return records
    _say_within_rounding(pb, found, not_ident, notes)
    gone = [id(w.key) for w in found]
    return [r for r in records if id(r) not in gone]


def _say_within_rounding(pb: LinearProblem, found: list[within_rounding.WithinRounding],
                         not_ident: dict[str, dict[str, str]], notes: list[str]) -> None:
    """The note and the not-identifiable entry of each channel finding not named."""
    src = pb.ctx.temperature_source
    col = LSB_COLUMNS.get(src, "an _lsb_c column")
    for w in found:
        why = within_rounding.why(w, src, col)
        notes.append(f"{w.effect} not named: {why}")
        not_ident[w.effect] = {
            "effect": w.effect, "why": why,
            "experiment": (f"declare the channel's LSB ({col}), or record the temperature with "
                           f"a channel that dithers or is finer; {BY_ID[w.effect].experiment}")}


def _shape_after_turn(pb: LinearProblem, terms: list[Term], findings: list[Finding],
                      alpha: float, notes: list[str]
                      ) -> tuple[list[Term], list[Finding], list[dict[str, Any]]]:
    """Withdraw the named terms whose shape the data do not follow, judged after the turn
    check (``CatalogueEffect.shape_after_turn``); as :func:`_physics_checks` returns."""
    named = [f for f in findings if f.named_as_modelled and not f.rows
             and BY_ID[f.effect].checks_shape_after_turn]
    if not named:
        return terms, findings, []
    U, yw = _basis(pb, terms)
    e = yw - U @ (U.T @ yw)
    out: list[dict[str, Any]] = []
    gone: set[TermKey] = set()
    for f in named:
        place = BY_ID[f.effect].shape_after_turn(pb, U, e, f.axes, alpha)
        if place is not None:
            out.append({"effect": f.effect, **place, "p_value": f.p_value, "test": f.test})
            gone |= f.term_keys
    if gone:
        terms, findings, _ = withdraw(terms, findings, gone)
        _note_not_named(out, notes)
    return terms, findings, out


def _inside_withdrawn_runs(pb: LinearProblem, terms: list[Term], findings: list[Finding],
                           not_named: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Flagged readings inside a run in time already withdrawn as structure (issue 22).

    A run of readings that moves together on a plateau (a crack or a step in the middle
    of it) may be flagged reading by reading; the first withdrawn by its time companions
    leaves the next, judged against a model that still holds the first's term, standing
    alone. A reading on the same plateau within the withdrawn run's time span belongs to
    that run: it is not isolated either.
    """
    runs = [n for n in not_named if n.get("kind") == "time"]
    done = {(n["effect"], n.get("row")) for n in not_named}
    out: list[dict[str, Any]] = []
    ctx = pb.ctx
    for t in terms:
        if not t.rows or (t.effect_id, t.rows[0]) in done:
            continue
        i = t.rows[0]
        run = next((n for n in runs if int(ctx.steps[i]) in n["steps"]
                    and n["time_s"][0] <= ctx.t_s[i] <= n["time_s"][1]), None)
        if run is None:
            continue
        f = _finding_of(findings, t)
        out.append({**run, "effect": t.effect_id, "row": i, "p_value": f.p_value,
                    "test": f.test, "why": (f"it lies in the run of readings withdrawn at "
                                            f"reading {run['row']} ({run['why']})")})
    return out


def _turned_or_bent(pb: LinearProblem, terms: list[Term], f: Finding, alpha: float,
                    not_ident: dict[str, dict[str, str]], notes: list[str]) -> Finding:
    """A function of the specific force named only if it changes the force's length.

    Why (issue 22): a rig geometry error (a tilted table axis, an encoder error) makes the
    true specific force differ from the recorded reference by a rotation, δ ⊥ ref, the
    same at every visit of a direction: a function of the reference direction, as a sensor
    nonlinearity is. The catalogue's nonlinearities (``a_i²``, ``a_i³``, ``a_i·a_j``) also
    change the output *along* the reference. So a turn is put in the model (fields across
    the reference of the nonlinearities' own degree, ``turntable_geometry.turn_columns``)
    and the term's part along the reference is tested after it (F, at α). If it is not
    needed, the structure only turns the reference: without the
    table angles (not in the recording format) that cannot be told from
    ``turntable_geometry``, and the finding is reported as not identifiable with both
    candidates (the term stays in the model: either removes the structure).
    """
    eff = BY_ID.get(f.effect)
    if eff is None or not eff.input_only or pb.mode != "reference" or f.rows:
        return f
    term = next((t for t in terms if t.key in f.term_keys), None)
    if term is None:
        return f
    ctx = pb.ctx
    u = ctx.input_g / np.linalg.norm(ctx.input_g, axis=1, keepdims=True)
    # The design's size from the turn's column count (one reading's columns), before the
    # (N, 3, k) columns are built: on a long recording they were the peak (issue 22, memory:
    # 1.4 GB with their stacking copy at 1 M readings, for a check that is then skipped).
    p = pb.X0.shape[1] + sum(t.X.shape[1] for t in terms) + turn_columns(u[:1]).shape[2]
    if 8 * pb.m * p > stats.TALL_BYTES or pb.m <= p + 10:
        notes.append(f"{f.effect}: not checked against a turn of the reference (a table "
                     "tilt or encoder error): the recording is too long for that design")
        return f
    turn = turn_columns(u)
    X = eff.regressors(ctx, term.theta)
    along = np.einsum("nak,na->nk", X, u)[:, None, :] * u[:, :, None]
    turned = Term("turn", float("nan"), pb.lift(turn))
    Xw, yw = _design(pb, [t for t in terms if t is not term] + [turned])
    U = stats.orthonormal_basis(Xw)
    del Xw
    e = yw - U @ (U.T @ yw)
    lp = stats.linear_stats(U, pb.whiten(pb.lift(along)), e, e[:, None])[0]  # F on the data
    p_along = float(np.exp(lp))
    if p_along <= alpha:
        return f
    geo = TURNTABLE_GEOMETRY
    why = (f"the structure turns the reference direction without changing its length (the "
           f"{f.effect} term's part along the reference is not needed once each direction "
           f"may turn: p = {p_along:.2g} > α); {_table_turn_clause(pb, not_ident)}")
    candidates = [f.effect, geo.effect_id]
    for c in candidates:
        other = candidates[1] if c == candidates[0] else candidates[0]
        not_ident[c] = {"effect": c, "why": f"not separable from {other}: {why}",
                        "experiment": (geo.experiment_for(pb.ctx) if c == geo.effect_id
                                       else BY_ID[c].experiment)}
    return replace(
        f, effect="not_identifiable", where={**f.where, "candidates": candidates},
        explanation=(f"Structure beyond noise that {' or '.join(candidates)} explain alike: "
                     f"{why}. It is modelled (with the {f.effect} term) but not named; "
                     f"to separate them: {geo.experiment_for(pb.ctx)}."),
        parameters={}, parameter_sd={}, confusers=[])


def _table_turn_clause(pb: LinearProblem, not_ident: dict[str, dict[str, str]]) -> str:
    """What the table's geometry could say of a turn of the reference, as this recording
    allows: without poses nothing tells them apart; with them a tilted base was tested
    (not an encoder error's or a wobble's turn of each pose), unless the protocol kept the
    table's test from running (then why)."""
    geo = TURNTABLE_GEOMETRY.effect_id
    if pb.ctx.pose_q is None:
        return ("a tilted table axis or an encoder error does exactly that, and the recording "
                "holds the reference in the sensor frame, not the table angles that would "
                "tell them apart")
    if geo in not_ident:
        return ("a tilted table axis or an encoder error does exactly that; the recorded "
                "poses would test the tilt, but not here: " + not_ident[geo]["why"])
    return ("a tilted table base, tested through the recorded poses, does not explain it, "
            "but an encoder error or a wobbling axis turns each pose by its own angle, and "
            "the poses give no axis angles to tell them apart")


def _unexplained_finding(pb: LinearProblem, res: scan_mod.ScanResult,
                         final_res: np.ndarray, not_named: list[dict[str, Any]] | None = None,
                         left_structure: list[str] | None = None) -> Finding:
    """``unexplained``: where structure was found, not what it is (effects.md).

    ``not_named``: the places of terms withdrawn by their physics checks; their family
    p is the evidence when the scan alone is not significant (the structure was found,
    only the name failed). ``left_structure``: effects the family test found whose terms
    were withdrawn because the scan still finds structure at their own places; they are
    the finding's ``candidates`` (seen here, not established), as for structure that
    held-out data did not confirm (not_confirmed.py).
    """
    ctx = pb.ctx
    not_named = not_named or []
    places = list(res.places) if res.significant else []
    for n in not_named:  # a run in time is a place on its plateau; the others, positions
        in_time = n.get("kind") == "time"
        places.append({"not_named": n["effect"], "kind": n.get("kind", "visits"),
                       **({"row": n["row"]} if "row" in n else {}),
                       "steps": n["steps"] if in_time else [],
                       "positions": [] if in_time else n["positions"],
                       **({"time_s": n["time_s"]} if in_time else {}),
                       "axis": "/".join(n["axes"]), "log10_p": n["log10_p"], "why": n["why"]})
    steps = sorted({p["step"] for p in places if "step" in p}
                   | {s for p in places for s in p.get("steps", [])})
    pos = sorted({p["position"] for p in places if "position" in p}
                 | {q for p in places for q in p.get("positions", [])})
    axes = sorted({a for p in places for a in p["axis"].split("/")})
    rows = np.isin(ctx.steps, steps) | np.isin(ctx.positions, pos)
    span = ([float(ctx.t_s[rows].min()), float(ctx.t_s[rows].max())] if rows.any()
            else [float(ctx.t_s.min()), float(ctx.t_s.max())])
    parts = []
    if steps:
        parts.append("step(s) " + ", ".join(f"{s} ({ctx.step_temp_c.get(s, float('nan')):.0f} °C)"
                                            for s in steps))
    if pos:
        parts.append("position(s) " + ", ".join(str(p) for p in pos))
    why = "".join(dict.fromkeys(f" Not named {n['effect']}: {n['why']}." for n in not_named))
    p_value, test = res.p_family, res.to_dict()["test"]
    if not res.significant:  # found by the withdrawn terms' tests; only their names failed
        first = min(not_named, key=lambda n: n["p_value"])
        p_value, test = first["p_value"], f"{first['test']} (found; not named: physics check)"
    rms = _rms(final_res, np.zeros(ctx.n, bool))
    where: dict[str, Any] = {"steps": steps, "positions": pos, "time_s": span, "places": places}
    if left_structure:
        where["candidates"] = list(left_structure)
        why += (f" Found by the family test, not named: {', '.join(left_structure)} (with "
                "its term fitted, structure remains at the steps/positions where it acts).")
    return Finding(
        effect="unexplained", axes=axes, where=where,
        explanation=(f"Structure beyond noise at {' and '.join(parts)} on axis "
                     f"{'/'.join(axes)} that no catalogue term explains; the data show where, "
                     f"not what.{why}"),
        parameters={}, parameter_sd={}, rmse_before_ug=rms, rmse_after_ug=rms,
        heldout_rmse_before_ug=float("nan"), heldout_rmse_after_ug=float("nan"),
        p_value=p_value, test=test)


def _excess_finding(pb: LinearProblem, chi_square: dict[str, Any], located: dict[str, Any],
                    final_res: np.ndarray) -> Finding:
    """``unexplained``: residuals far above the recorded noise (the χ² excess test, p < α and
    χ²/dof > :data:`EXCESS_CHI2_RED`) that no test located or named. Its ``where`` holds the
    readings whose residual stands out most (``located["outlying_rows"]``), or the whole
    recording. The verdict is then "mismatch", not "consistent": the residuals are not
    consistent with noise (the CLI contract), whichever of the two causes the text names."""
    ctx = pb.ctx
    rows = np.asarray(located.get("outlying_rows") or [], int)
    steps = sorted({int(s) for s in ctx.steps[rows]})
    pos = sorted({int(q) for q in ctx.positions[rows]})
    t = ctx.t_s[rows] if rows.size else ctx.t_s
    rms = _rms(final_res, np.zeros(ctx.n, bool))
    at = (f"; the readings that stand out most: {', '.join(str(int(r)) for r in rows)}"
          if rows.size else "")
    return Finding(
        effect="unexplained", axes=list(AXES) if pb.mode == "reference" else ["norm"],
        where={"steps": steps, "positions": pos, "time_s": [float(t.min()), float(t.max())],
               "rows": [int(r) for r in rows], "spread": True},
        explanation=(f"The final residual is {chi_square['rms_over_noise']:.2f} × the recorded "
                     f"noise (χ²/dof {chi_square['chi2_per_dof']:.2f} on {chi_square['dof']} "
                     "dof) and no test located or named it: either the recorded noise "
                     "understates the scatter (correlated samples, vibration, placement "
                     "repeatability) or structure the catalogue does not name is spread over "
                     f"the recording{at}. Repeat positions or plateaus to locate it."),
        parameters={}, parameter_sd={}, rmse_before_ug=rms, rmse_after_ug=rms,
        heldout_rmse_before_ug=float("nan"), heldout_rmse_after_ug=float("nan"),
        p_value=float(chi_square["p_value"]), test=chi_square["test"])


def _excess_within_rounding(pb: LinearProblem, res_g: np.ndarray, flagged: np.ndarray,
                            box: stats.BoundedShared, terms: list[Term], alpha: float) -> bool:
    """Whether the χ² excess (:func:`_excess_test`) goes once each plateau's temperature
    error within the channel's rounding ``box`` (|δ_g| ≤ half, each entry moved by its
    loading·δ_g) is fitted out of the final residual: per group the least-squares δ_g
    clipped to the box, one degree of freedom per group taken. Not an error the
    recording can resolve, so not a mismatch it can call (docs/diagnosis.md §7)."""
    z = res_g * pb.w
    keep = ~flagged[pb.row]
    grp = np.asarray(box.group)
    load = np.asarray(box.loading, float)
    n_g = int(grp.max()) + 1 if grp.size else 0
    num = np.bincount(grp[keep], weights=(load * z)[keep], minlength=n_g)
    den = np.bincount(grp[keep], weights=(load * load)[keep], minlength=n_g)
    delta = np.clip(np.divide(num, den, out=np.zeros(n_g), where=den > 0), -box.half,
                    box.half)
    net = (z - load * delta[grp])[keep]
    return not _chi2_excess(net, _n_columns(pb, terms) + n_g, alpha)[3]


def _n_columns(pb: LinearProblem, terms: list[Term]) -> int:
    """The final model's columns: the base's and every accepted term's (no (m × p) copy)."""
    return pb.X0.shape[1] + sum(t.X.shape[1] for t in terms)


def _chi2_excess(z: np.ndarray, n_cols: int, alpha: float) -> tuple[float, int, float, bool]:
    """(χ²/dof, dof, p, significant) of whitened residual entries ``z`` after ``n_cols``
    fitted columns: significant only if p < α *and* χ²/dof > :data:`EXCESS_CHI2_RED` (the
    one rule of :func:`_excess_test` and :func:`_excess_within_rounding`)."""
    from scipy.stats import chi2

    dof = max(z.size - n_cols, 1)
    c2 = float(z @ z)
    p = float(chi2.sf(c2, dof))
    red = c2 / dof
    return red, dof, p, bool(p < alpha and red > EXCESS_CHI2_RED)


def _columns_of(terms: list[Term], one_step_seen: list[one_step_report.OneStep],
                f: Finding) -> np.ndarray | None:
    """The raw columns a finding's structure was found with: its terms' (a finding kept in
    the model), else the one-plateau candidates' the family test chose; None without."""
    keys = f.term_keys
    X = [t.X for t in terms if t.key in keys] if keys else [
        r.X for r in one_step_seen if r.effect_id in (f.where.get("candidates") or [])]
    return np.hstack(X) if X else None


def _excess_test(pb: LinearProblem, res_g: np.ndarray, flagged: np.ndarray,
                 terms: list[Term], alpha: float) -> dict[str, Any]:
    """χ² of the final residual against the recorded noise sd/√n (only when sd is recorded).

    Significant only if p < α *and* χ²/dof > :data:`EXCESS_CHI2_RED`: sd/√n of real
    averages is often optimistic by a few tens of %, which is not physics.
    """
    if not pb.noise_from_sd:
        return {"test": "not run: no sd_* columns, noise estimated from the residuals"}
    if pb.between_sd_g is not None and not pb.noise_within_plateaus:
        # σ was matched to this residual: χ² ≈ dof by design
        return {"test": "not run: raw samples, the between-capture noise is estimated from "
                        "the residuals"}
    red, dof, p, significant = _chi2_excess((res_g * pb.w)[~flagged[pb.row]],
                                            _n_columns(pb, terms), alpha)
    against = ("the scatter within plateaus (kappa*sd^2/n + tau^2)"
               if pb.noise_within_plateaus else "sd/sqrt(n)")
    return {"test": f"chi-square of the residuals against {against}", "chi2_per_dof":
            round(red, 3), "dof": dof, "p_value": float(f"{p:.3g}"),
            "significant": significant,
            "rms_over_noise": round(float(np.sqrt(red)), 3)}


def _evaluate(pb, live, rejected, terms, U, e, E, s, s_null, lifted, not_ident,
              tail=(np.inf, None), bounded: stats.BoundedShared | None = None):
    """Each live effect's test at this stage. ``bounded``: a quantised channel's rounding
    error, which each data score is taken net of (stats.linear_stats, stats.row_stats)."""
    tests: dict[str, stats.CandidateTest] = {}
    # A per-reading effect may be accepted again at another reading; any other once.
    chosen = {t.effect_id for t in terms if not BY_ID[t.effect_id].per_reading}
    EE = stats.sum_sq_columns(E)  # once per stage, not once per candidate and grid value
    for eff in live:
        if eff.effect_id in chosen or eff.effect_id in rejected:
            continue
        if eff.per_reading:
            skip = {r for t in terms for r in t.rows}
            nu, rng = tail  # the readings' own tail (ν = ∞: Gaussian), see _reading_dof
            t_row, tn, g = stats.row_stats(U, e, E, pb.row, pb.ctx.n, s, s_null, skip,
                                           pb.shared_t_loading, nu, rng, bounded)
            i = int(np.argmax(t_row))
            mult = pb.ctx.n - len(skip)
            lp = float(stats.reading_logsf(t_row[i], g, nu))
            tests[eff.effect_id] = stats.CandidateTest(
                eff.effect_id, lp, mult, float(stats.sidak_log(lp, mult)),
                stats.sidak_log(stats.reading_logsf(tn, g, nu), mult), float(i), 0.0,
                float(t_row[i]))
            continue
        grid = eff.grid(pb.ctx)
        best_lp, best_theta, best_q, absorbed_min = np.inf, float("nan"), 0.0, 1.0
        profile: dict[float, float] = {}
        null_lp = np.zeros(E.shape[1])
        usable = 0
        for theta in grid:
            Xw = pb.whiten(lifted(eff, theta))
            if Xw.shape[1] == 0 or not np.any(Xw):
                continue
            own = eff.test_stats(pb, U, Xw, e, E)  # an effect with its own noise scale
            if own is not None and bounded is not None:
                # With a quantised channel its data score is taken on the residual whose
                # part along its columns is shortened by the box's reach, as linear_stats
                # takes the others' (else it escaped the bound and won the name over those
                # that did not: cross_coupling named turntable_geometry on the clean channel)
                e_net = bounded.shortened(
                    stats.orthonormal_basis(stats.project_out(U, Xw), 1e-6), e)
                own = (eff.test_stats(pb, U, Xw, e_net, E[:, :1])[0], *own[1:])
            lp, lpn, k, absorbed, q = (own if own is not None else
                                       stats.linear_stats(U, Xw, e, E, eff.one_sided, EE,
                                                          bounded))
            absorbed_min = min(absorbed_min, absorbed)
            if k == 0 or absorbed > eff.absorbed_max:
                continue
            usable += 1
            profile[theta] = lp
            null_lp = np.minimum(null_lp, lpn)
            if lp < best_lp:
                best_lp, best_theta, best_q = lp, theta, q
        if usable == 0:
            if not terms and eff.effect_id not in not_ident:
                not_ident[eff.effect_id] = {
                    "effect": eff.effect_id,
                    "why": (f"the base model absorbs {100 * absorbed_min:.1f} % of it in this "
                            "protocol"),
                    "experiment": eff.experiment}
            continue
        tests[eff.effect_id] = stats.CandidateTest(
            eff.effect_id, float(best_lp), usable, float(stats.sidak_log(best_lp, usable)),
            stats.sidak_log(null_lp, usable), best_theta, absorbed_min, best_q, profile)
    return tests


REFINE_XTOL_LOG = 1e-3  # relative resolution of a refined continuous theta


def _refine(pb: LinearProblem, eff: CatalogueEffect, test: stats.CandidateTest, U: np.ndarray,
            e: np.ndarray) -> tuple[stats.CandidateTest, np.ndarray]:
    """Refine a continuous θ (lag τ) between its grid neighbours; sd from the profile curvature.

    Why: the grid (18 values over two decades) is fine enough for the *test*, but a strong
    lag fitted at a grid value 15 % off τ leaves residuals far above the noise, which the
    next stages would then explain with spurious terms. The test and its null used the grid,
    so refining the accepted term does not change its p-value. Returns the refined test and
    the term's columns (lifted, unweighted).
    """
    from scipy.optimize import minimize_scalar

    def coef_of(X_raw: np.ndarray) -> np.ndarray:
        Z = stats.project_out(U, pb.whiten(pb.lift(X_raw)))
        return np.linalg.lstsq(Z, e, rcond=None)[0]

    def columns(log_theta: float) -> np.ndarray:
        return pb.lift(eff.refined_regressors(pb.ctx, float(np.exp(log_theta)), coef_of))

    def q_of(log_theta: float) -> tuple[float, int]:
        return stats.explained_ss(U, pb.whiten(columns(log_theta)), e, eff.one_sided)

    grid = sorted(test.profile)
    i = grid.index(test.theta)
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    x0 = float(np.log(test.theta))
    q0, k = q_of(x0)
    best_x, best_q = x0, q0
    if hi > lo:
        r = minimize_scalar(lambda x: -q_of(x)[0], bounds=(np.log(lo), np.log(hi)),
                            method="bounded", options={"xatol": REFINE_XTOL_LOG})
        if -r.fun > q0:
            best_x, best_q = float(r.x), float(-r.fun)
    # Profile likelihood: RSS(θ) = ‖e‖² − q(θ); 1 sd where it rises by one noise variance.
    dof = max(e.size - U.shape[1] - k, 1)
    s2 = max((float(e @ e) - best_q) / dof, 1e-300)
    h = 0.02
    curv = (q_of(best_x + h)[0] + q_of(best_x - h)[0] - 2.0 * best_q) / h**2
    theta = float(np.exp(best_x))
    sd = theta * float(np.sqrt(2.0 * s2 / -curv)) if curv < 0 else float("nan")
    return replace(test, theta=theta, stat=best_q, theta_sd=sd), columns(best_x)


def _make_term(pb: LinearProblem, eff: CatalogueEffect, test: stats.CandidateTest, lifted,
               X: np.ndarray | None = None) -> Term:
    if eff.per_reading:
        i = int(test.theta)
        X = pb.lift(eff.regressors(pb.ctx, float(i)))
        return Term(eff.effect_id, float(i), X, (i,))
    X = lifted(eff, test.theta) if X is None else X
    return Term(eff.effect_id, test.theta, X, (), test.theta_sd)


def _explained(pb: LinearProblem, U: np.ndarray, e: np.ndarray, lifted,
               eff: CatalogueEffect, theta: float) -> tuple[float, int]:
    """Explained SS of an effect's test columns at θ after the current model (by_fit)."""
    return stats.explained_ss(U, pb.whiten(lifted(eff, theta)), e, eff.one_sided)


def _design(pb: LinearProblem, terms: list[Term], whiten: bool = True):
    X = np.hstack([pb.X0] + [t.X for t in terms])
    if whiten:
        X *= pb.w[:, None]  # in place: the hstack is already a fresh copy
        return X, pb.y * pb.w
    return X, pb.y


def _heldout_in_noise_units(pb: LinearProblem, terms: list[Term], term: Term,
                            fold_masks: list[np.ndarray], excl: np.ndarray
                            ) -> tuple[float, float]:
    """Held-out prediction error in units of the noise, without and with ``term``."""
    before, after = (_heldout_ug(pb, ts, fold_masks, excl, in_noise_units=True)
                     for ts in (terms, terms + [term]))
    return before, after


def _heldout_ug(pb: LinearProblem, terms: list[Term], fold_masks: list[np.ndarray],
                excl: np.ndarray, in_noise_units: bool = False) -> float:
    """Held-out RMS of the model of ``terms`` (heldout.py); by row blocks of the whitened
    design above ``stats.TALL_BYTES`` (see :func:`_tall_rows`), else on the whole design."""
    shrunk = _shrunk_columns(pb, terms)
    if _tall_rows(pb, terms) is not None:
        return heldout_rms_ug_by_blocks(WhitenedDesign([pb.X0] + [t.X for t in terms], pb.w),
                                        pb.y, pb.row, fold_masks, excl, shrunk, in_noise_units)
    X, y = _design(pb, terms, whiten=False)
    return heldout_rms_ug(y, X, pb.w, pb.row, fold_masks, excl, shrunk, in_noise_units)


def _shrunk_columns(pb: LinearProblem, terms: list[Term]) -> np.ndarray | None:
    """(p,) columns whose held-out fit is shrunk (``CatalogueEffect.shrunk_heldout``)."""
    flags = [np.zeros(pb.X0.shape[1], bool)] + [
        np.full(t.X.shape[1], BY_ID[t.effect_id].shrunk_heldout) for t in terms]
    out = np.concatenate(flags)
    return out if out.any() else None


def _tall_rows(pb: LinearProblem, terms: list[Term]):
    """Row blocks ``rows(i, j)`` of the whitened design, or None when it is built whole.

    Why (issue 10, memory): above ``stats.TALL_BYTES`` (the tall path of
    ``stats.orthonormal_basis``) the whitened design is never materialised: at 1 M readings
    it was a 1.15 GB copy next to the base design and the basis, the largest of diagnose's
    peak. Shorter recordings keep the whole-array code, so their answers are unchanged.
    """
    p = pb.X0.shape[1] + sum(t.X.shape[1] for t in terms)
    if 8 * pb.m * p <= stats.TALL_BYTES or pb.m <= 20 * p:
        return None

    def rows(i: int, j: int) -> np.ndarray:
        return np.hstack([pb.X0[i:j]] + [t.X[i:j] for t in terms]) * pb.w[i:j, None]

    return rows


def _basis(pb: LinearProblem, terms: list[Term]
           ) -> tuple[np.ndarray | RowBlockBasis, np.ndarray]:
    """Orthonormal basis of the whitened design of ``terms``, and the whitened data.

    Above ``stats.TALL_BYTES`` the basis is held as its recipe (basis.py, issue 22: at
    1 M readings the stored (m × r) basis was 1.15 GB, diagnose's largest array).
    """
    if _tall_rows(pb, terms) is not None:
        design = WhitenedDesign([pb.X0] + [t.X for t in terms], pb.w)
        return RowBlockBasis.of_design(design), pb.y * pb.w
    Xw, yw = _design(pb, terms)
    return stats.orthonormal_basis(Xw), yw


def _fit(pb: LinearProblem, terms: list[Term]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """WLS of the current model: coefficients, covariance (× reduced χ²), residual (g)."""
    if _tall_rows(pb, terms) is not None:
        return _fit_by_blocks(pb, terms)
    Xw, yw = _design(pb, terms)
    scale = column_scale(Xw)  # why: effect columns may be 10⁷ smaller than the base's
    Xs = Xw
    Xs /= scale  # in place: _design's copy is ours
    G = Xs.T @ Xs
    Ginv = np.linalg.pinv(G, rcond=1e-12, hermitian=True)
    beta_s = Ginv @ (Xs.T @ yw)
    r = yw - Xs @ beta_s
    dof = max(pb.m - int(round(np.trace(Ginv @ G))), 1)
    chi2_red = float(r @ r) / dof
    cov = Ginv * chi2_red / np.outer(scale, scale)
    return beta_s / scale, cov, r / pb.w


def term_coefficients(diag: Diagnosis) -> list[tuple[Term, np.ndarray, np.ndarray]]:
    """Each final term of ``diag`` with its coefficients in the joint fit with the base and
    their standard errors (the fit's covariance, scaled by its reduced χ² as :func:`_fit`
    scales it).

    Why: a term's raw output at any reading is its effect's regressors times these
    (``lift`` is linear), which is what a twin carries to another recording
    (:mod:`calibration.discrepancy.twin_effects`). Empty when nothing was modelled.
    """
    pb = diag.problem
    if pb is None or not diag.terms:
        return []
    beta, cov, _ = _fit(pb, diag.terms)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out, i = [], pb.X0.shape[1]
    for t in diag.terms:
        k = t.X.shape[1]
        out.append((t, beta[i:i + k].copy(), sd[i:i + k].copy()))
        i += k
    return out


def _fit_by_blocks(pb: LinearProblem, terms: list[Term]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_fit` by row blocks of the whitened design (see :func:`_tall_rows`).

    The same normal equations on unit-norm columns: G = XᵀX and Xᵀy summed by blocks,
    the column norms from diag(G), the residual y − Xβ by blocks.
    """
    rows = _tall_rows(pb, terms)
    yw = pb.y * pb.w
    p = pb.X0.shape[1] + sum(t.X.shape[1] for t in terms)
    G, h = np.zeros((p, p)), np.zeros(p)
    for sl in stats.row_blocks(pb.m, p):
        B = rows(sl.start, sl.stop)
        G += B.T @ B
        h += B.T @ yw[sl]
    scale = np.sqrt(np.diag(G))
    scale = np.where(scale > 0, scale, 1.0)
    Gs = G / np.outer(scale, scale)
    Ginv = np.linalg.pinv(Gs, rcond=1e-12, hermitian=True)
    beta = (Ginv @ (h / scale)) / scale
    r = yw.copy()
    for sl in stats.row_blocks(pb.m, p):
        r[sl] -= rows(sl.start, sl.stop) @ beta
    dof = max(pb.m - int(round(np.trace(Ginv @ Gs))), 1)
    chi2_red = float(r @ r) / dof
    cov = Ginv * chi2_red / np.outer(scale, scale)
    return beta, cov, r / pb.w


def _residual(pb: LinearProblem, terms: list[Term]) -> np.ndarray:
    return _fit(pb, terms)[2]


def _flagged(pb: LinearProblem, terms: list[Term]) -> np.ndarray:
    m = np.zeros(pb.ctx.n, bool)
    for t in terms:
        m[list(t.rows)] = True
    return m


def _rms(res_g: np.ndarray, flagged_rows: np.ndarray) -> float:
    return float(np.sqrt(np.mean(res_g**2)) * 1e6) if res_g.size else 0.0


def _not_confirmed(pb: LinearProblem, eff: CatalogueEffect, term: Term, terms: list[Term],
                   p_family: float, ho_b: float, ho_a: float,
                   fitted: tuple[np.ndarray, np.ndarray]) -> not_confirmed.NotConfirmed:
    """The record of a term held-out data did not confirm: where its fit acts
    (``fitted``: the model ``terms + [term]``'s coefficients and covariance)."""
    coef, se = _term_coefficients(pb, terms + [term], term, fitted)
    axes = ["norm"] if pb.mode == "norm" else list(eff.axes(coef, se))
    return not_confirmed.NotConfirmed(
        eff.effect_id, float(p_family), float(ho_b), float(ho_a), tuple(axes),
        where_of(pb, term.X @ coef, term.rows), term.X)


def _outside_earlier_terms(pb: LinearProblem, terms: list[Term], term: Term,
                           coef: np.ndarray) -> tuple[float, str | None]:
    """The share of ``term``'s fitted contribution (``coef``: its coefficients with the
    earlier ``terms``; whitened, after the base model) that the earlier terms cannot carry,
    and, when that share is below :data:`MIN_SHARE_OUTSIDE_TERMS`, the earlier term that
    carries most of it.

    1 when the term is orthogonal to them; near 0 when its columns, beyond the base, lie
    within theirs: fitted together the two then cancel, each with coefficients far beyond
    the structure (a cube of each axis's input beside a free turn of each table pose: a
    per-pose constant across the reference is a turn). ``(1, None)`` without earlier terms
    or on the row-block path (a tall recording)."""
    if not terms or _tall_rows(pb, terms + [term]) is not None:
        return 1.0, None
    v = (term.X @ coef) * pb.w

    def left(X: np.ndarray) -> float:
        X = X * pb.w[:, None]
        scale = column_scale(X)
        r = v - (X / scale) @ np.linalg.lstsq(X / scale, v, rcond=None)[0]
        return float(r @ r)

    base = left(pb.X0)
    if base <= 0.0:
        return 1.0, None
    share = left(np.hstack([pb.X0] + [t.X for t in terms])) / base
    if share >= MIN_SHARE_OUTSIDE_TERMS:
        return share, None
    by_term = {t.effect_id: left(np.hstack([pb.X0, t.X])) for t in terms}
    return share, min(by_term, key=by_term.__getitem__)


def _term_coefficients(pb: LinearProblem, terms: list[Term], term: Term,
                       fitted: tuple[np.ndarray, np.ndarray] | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """``term``'s fitted coefficients and standard errors in the model of ``terms`` (which
    holds it); ``fitted``: that model's (coefficients, covariance) when already fitted."""
    beta, cov = fitted if fitted is not None else _fit(pb, terms)[:2]
    offset = pb.X0.shape[1]
    for t in terms:
        if t is term:
            break
        offset += t.X.shape[1]
    k = term.X.shape[1]
    return (beta[offset:offset + k],
            np.sqrt(np.clip(np.diag(cov)[offset:offset + k], 0, None)))


def _stated(pb: LinearProblem, eff: CatalogueEffect, term: Term, coef: np.ndarray,
            se: np.ndarray, alpha: float
            ) -> tuple[dict[str, float], dict[str, float], list[str], str]:
    """What a finding states of its term's fit: parameters, their sd, the axes and the
    sentence. The one place of them (issue 22): the axes are those the effect is judged on
    (``CatalogueEffect.stated_axes``, the level ``alpha`` of its physics check), which the
    sentence names and the physics checks then read from the finding."""
    params, sd = eff.parameters(coef, se, term.theta, pb.ctx)
    if eff.continuous and eff.theta_name:
        sd[eff.theta_name] = term.theta_sd
    axes, clause = eff.stated_axes(pb, coef, se, alpha)
    if pb.mode == "norm" and eff.per_reading:
        axes = ["norm"]  # a |g| residual has no axis
    return params, sd, axes, _sentence(eff, params, sd, axes, pb.ctx, clause)


def _finding(pb, eff, test, term, terms, tests, p_family, rms_b, rms_a, ho_b, ho_a,
             fitted=None, *, alpha: float = ALPHA) -> Finding:
    coef, se = _term_coefficients(pb, terms, term, fitted)
    contrib = term.X @ coef
    params, sd, axes, text = _stated(pb, eff, term, coef, se, alpha)
    conf = []
    for c in eff.confusers:
        if c in tests:
            conf.append({"effect": c, "p_before": float(f"{tests[c].p_adj:.3g}"),
                         "p_after": None, "how_told_apart": how_told_apart(eff, BY_ID[c])})
    return Finding(
        effect=eff.effect_id, axes=axes, where=where_of(pb, contrib, term.rows),
        explanation=text, parameters=_round(params),
        parameter_sd=_round(sd), rmse_before_ug=rms_b, rmse_after_ug=rms_a,
        heldout_rmse_before_ug=ho_b, heldout_rmse_after_ug=ho_a, p_value=p_family,
        test=eff.test_name(), confusers=conf, theta=term.theta, rows=list(term.rows),
        term_effect=term.effect_id,
    )


def _restated(pb: LinearProblem, terms: list[Term], findings: list[Finding],
              alpha: float = ALPHA) -> list[Finding]:
    """The named findings' parameters, axes and sentences in the model of ``terms`` (one
    fit of it; ``alpha``: the physics checks' level, :func:`_stated`); any other finding,
    or one whose term is not there, as it is."""
    fitted: tuple[np.ndarray, np.ndarray] | None = None
    out = []
    for f in findings:
        term = (next((t for t in terms if t.key in f.term_keys), None)
                if f.named_as_modelled and f.effect in BY_ID else None)
        if term is None:
            out.append(f)
            continue
        if fitted is None:
            fitted = _fit(pb, terms)[:2]
        eff = BY_ID[f.effect]
        coef, se = _term_coefficients(pb, terms, term, fitted)
        params, sd, axes, text = _stated(pb, eff, term, coef, se, alpha)
        out.append(replace(f, axes=axes, parameters=_round(params), parameter_sd=_round(sd),
                           explanation=text))
    return out


def _sentence(eff: CatalogueEffect, params, sd, axes, ctx, clause: str = "") -> str:
    text = eff.sentence(params, sd, [a for a in axes if a in AXES] or list(AXES), ctx)
    if clause:
        text = text.rstrip(".") + "; " + clause
    return text[0].upper() + text[1:] + ("" if text.endswith(".") else ".")


def _round(d: dict[str, float]) -> dict[str, float]:
    return {k: float(f"{v:.4g}") if np.isfinite(v) else None for k, v in d.items()}


def _as_protocol_allows(f: Finding, protocol: Protocol, not_ident: dict[str, dict[str, str]],
                        alpha: float) -> Finding:
    """A finding as this recording's protocol lets it be stated (issue 10).

    A named member of a withholding confusion (members each testable here, not from each
    other under this protocol) whose confuser in that confusion was significant too before
    the term was added (p ≤ α: it explained the same structure) becomes ``not_identifiable``
    with every candidate in ``where`` and the text. The term stays in the model, since
    either candidate removes that structure, but no parameters or model-file term are given
    for a name the data cannot support. Other confusions that hold the effect add their
    untestable alternatives to ``confusers``.
    """
    if f.effect not in BY_ID:
        return f
    conf = protocol.withheld_with(f.effect)
    rivals = {c["effect"] for c in f.confusers
              if c.get("p_before") is not None and c["p_before"] <= alpha}
    if conf is not None and not rivals & set(conf.alternatives(f.effect)):
        conf = None  # the data told them apart here: the rival did not explain it
    if conf is None:
        # Only alternatives with no regressor: one that has one was tested (its p is in
        # ``confusers``) or cannot be in this recording's data (absorbed, dT/dt ≈ 0).
        extra = [{"effect": alt, "p_before": None, "p_after": None,
                  "how_told_apart": f"not separable in this protocol: {c.why}"}
                 for c in protocol.not_separable for alt in c.alternatives(f.effect)
                 if alt in BY_ID and not BY_ID[alt].observable
                 and alt not in {x["effect"] for x in f.confusers}]
        return replace(f, confusers=f.confusers + extra) if extra else f
    candidates = [f.effect] + [e for e in conf.alternatives(f.effect)
                               if e in rivals or (e in BY_ID and not BY_ID[e].observable)]
    for c in candidates:
        others = ", ".join(e for e in candidates if e != c)
        not_ident.setdefault(c, {"effect": c, "why": f"not separable from {others} in this "
                                 f"protocol: {conf.why}", "experiment": BY_ID[c].experiment})
    return replace(
        f, effect="not_identifiable", where={**f.where, "candidates": candidates},
        explanation=(f"Structure beyond noise that {' or '.join(candidates)} explain alike "
                     f"(each significant here): {conf.why}. It is modelled (with the "
                     f"{f.effect} term) but not named."),
        parameters={}, parameter_sd={}, confusers=[])


def _channel_glitches(pb: LinearProblem, terms: list[Term], findings: list[Finding],
                      alpha: float, not_ident: dict[str, dict[str, str]]) -> list[Finding]:
    """The ``outlier`` findings restated by their readings' glitch checks (channel_glitch.py),
    each judged against the model without any flagged reading's term."""
    rows = [r for f in findings if f.effect == channel_glitch.OUTLIER and f.named_as_modelled
            for r in f.rows]
    if not rows or pb.ctx.temperature_source == "none":
        return findings
    U, yw = _basis(pb, [t for t in terms if not t.rows])
    e = yw - U @ (U.T @ yw)
    skip = {r for t in terms for r in t.rows}
    checks = {r: channel_glitch.check_reading(pb, U, e, r, skip - {r}, alpha) for r in rows}
    return channel_glitch.restate(findings, checks, pb.ctx, not_ident)


def _merge_outliers(findings: list[Finding]) -> list[Finding]:
    """All readings a per-reading effect flagged become one finding, at the place of the first."""
    ids = [f.effect for f in findings if f.effect in BY_ID and BY_ID[f.effect].per_reading]
    for eid in dict.fromkeys(ids):
        findings = _merge_rows(findings, eid)
    return findings


def _merge_rows(findings: list[Finding], eid: str) -> list[Finding]:
    outs = [f for f in findings if f.effect == eid]
    if len(outs) <= 1:
        return findings
    first = outs[0]
    rows = [r for f in outs for r in f.rows]
    steps = sorted({s for f in outs for s in f.where["steps"]})
    pos = sorted({p for f in outs for p in f.where["positions"]})
    t_lo = min(f.where["time_s"][0] for f in outs)
    t_hi = max(f.where["time_s"][1] for f in outs)
    merged = Finding(
        effect=eid, axes=sorted({a for f in outs for a in f.axes}),
        where={"steps": steps, "positions": pos, "time_s": [t_lo, t_hi], "rows": rows},
        explanation=first.explanation.replace("1 reading(s)", f"{len(rows)} reading(s)", 1),
        parameters={**first.parameters, "n_rows": float(len(rows))},
        parameter_sd=first.parameter_sd, rmse_before_ug=first.rmse_before_ug,
        rmse_after_ug=outs[-1].rmse_after_ug,
        heldout_rmse_before_ug=first.heldout_rmse_before_ug,
        heldout_rmse_after_ug=outs[-1].heldout_rmse_after_ug,
        p_value=first.p_value, test=first.test, confusers=first.confusers, rows=rows,
        term_effect=first.term_effect)
    out, placed = [], False
    for f in findings:
        if f.effect == eid:
            if not placed:
                out.append(merged)
                placed = True
            continue
        out.append(f)
    return out
