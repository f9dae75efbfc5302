"""The one small interface every catalogue effect implements (effects.md).

Each effect is one frozen :class:`CatalogueEffect` instance (defined in its own module,
listed in ``ALL_EFFECTS``). It says how the physics would show in the raw output of each
reading (``regressors``: (N,3,k) g per unit parameter), over a grid of its
nonlinear parameter if it has one (``grid``: profile), whether a protocol can
reveal it at all (``identifiable``), and how to say what was found
(``parameters`` with uncertainties, ``sentence``), how it is told apart from
each confuser (``told_apart``), and what it adds to a model file
(``extension_fields``, ``extension_term_g``, ``apply_extension``: written and
registered by :mod:`calibration.discrepancy.extensions`). Its twin counterpart
is the class with the same ``effect_id`` in ``simulators/effects.py``
(``from_finding``): the simulators import the calibration side, never the
reverse (the one-way doors, checked by ``make test``). Whether the *base model* absorbs
it is measured, not declared: ``absorbed_fraction`` in :mod:`calibration.discrepancy.stats`.

Adding an effect is one module here plus its entry in ``ALL_EFFECTS``; nothing
in ``diagnose``, ``extensions`` or ``report`` names effect ids.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.discrepancy.context import AXES, DesignContext

UG = 1e6  # g → µg


@dataclass(frozen=True)
class CatalogueEffect:
    """One catalogue effect (an instance, listed in ``ALL_EFFECTS``).

    The base is a linear effect with no nonlinear parameter; subclasses override what differs.
    """

    effect_id: str = ""
    confusers: tuple[str, ...] = ()
    experiment: str = ""
    needs_motion: bool = False
    # θ is a continuous parameter (e.g. a lag τ): the winner's θ is refined between its grid
    # neighbours; ``theta_name`` is its name in ``parameters`` (its sd comes from the profile).
    continuous: bool = False
    theta_name: str = ""
    # ``one_sided``: the first regressor's coefficient is physically ≥ 0 (a lag's
    # amplitude); the test is the likelihood ratio under that constraint (stats.py).
    one_sided: bool = False
    # ``per_reading``: tested reading by reading (leave-one-reading-out, the max over readings
    # calibrated by the null), may be accepted at several readings, and flagged readings are
    # excluded from the scores (the ``outlier`` of effects.md). ``theta`` is then the row.
    per_reading: bool = False
    # How this effect is told apart from each of its confusers: (confuser id, text). A pair is
    # written once, in either module; :func:`how_told_apart` looks in both.
    told_apart: tuple[tuple[str, str], ...] = ()
    # Model-file term ``discrepancy.<effect_id>`` (extensions.py): written for a finding when
    # True. ``extension_absorbed``: the term depends on the input only, so the base model fitted
    # with it present absorbed its affine-in-input part; the file stores that part.
    writes_extension: bool = False
    extension_absorbed: bool = False
    # False: no regressor exists for it in a static soak recording (not_identifiable.py); it
    # can be in the data without being testable, so the report names it as an alternative.
    observable: bool = True
    # True: the term is a function of the specific force alone (a nonlinearity, products of
    # axes' inputs). It must then leave the same residual at every visit of the same
    # reference direction: :meth:`misses` tests that after selection (issue 10).
    input_only: bool = False
    checks_shape_after_turn: bool = False  # True where shape_after_turn is implemented
    # Largest fraction of the term's norm² the base model may absorb before the term is
    # declared not identifiable here (stats.ABSORBED_MAX). A term that is by construction
    # mostly a re-map of the base's own terms (a temperature-channel step) is judged by the
    # power of its remnant instead, with the same bootstrap null.
    absorbed_max: float = 0.99
    # True: one free parameter per place (a turn of each table pose); its held-out
    # prediction fits them with an empirical-Bayes ridge (heldout._shrunk_fit), not freely.
    shrunk_heldout: bool = False
    # Named among its significant confusers (that set it too) only as the clearly best fit,
    # else reported not identifiable with the close ones (by_fit.py, issue 22).
    named_by_fit: bool = False
    # ``twin fit`` (twin_effects.py, docs/diagnosis.md §10) carries a finding of this effect
    # into the twin when its coefficients mean the same in any recording of the sensor:
    # physics a new campaign meets again. Otherwise ``twin_omitted`` says why it is left out.
    twin_carries: bool = False
    twin_omitted: str = "the twin does not carry it in this build"

    # --- design -----------------------------------------------------------
    def grid(self, ctx: DesignContext) -> list[float]:
        """Values of the nonlinear parameter to profile over (``[nan]`` when linear)."""
        return [float("nan")]

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        """(N,3,k) change of raw output (g) per unit of each linear parameter."""
        raise NotImplementedError

    def refined_regressors(self, ctx: DesignContext, theta: float,
                           coef_of: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """Regressors of an *accepted* term, which may adapt to the data.

        ``coef_of(X)`` fits (N,3,k) columns to the current residual and returns the k
        coefficients. Default: the test's regressors unchanged. The test and its null
        always use :meth:`regressors`.
        """
        return self.regressors(ctx, theta)

    def test_stats(self, pb: Any, U: np.ndarray, Xw: np.ndarray, e: np.ndarray,
                   E: np.ndarray) -> tuple[float, np.ndarray, int, float, float] | None:
        """The test's (log p, log p per null replicate, dof, absorbed fraction, explained SS)
        when the effect scales it by a noise of its own; None: ``stats.linear_stats``."""
        return None

    def cause_recorded(self, ctx: DesignContext) -> bool:
        """The recording itself logs the event this effect follows, unrelated to the
        temperature (a power cycle in a ``session`` column): a jump of the output at a
        temperature that coincides with it is then no rival (temperature_jump.py).
        Default: False."""
        return False

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        """Protocol-level check: (can this recording show it, why not, experiment that would)."""
        if self.needs_motion:
            return (False, "it acts only while the table rotates; every reading here is static",
                    self.experiment)
        return True, "", self.experiment

    def misses(self, pb: Any, U: np.ndarray, e: np.ndarray, theta: float,
               where: Mapping[str, Any], axes: list[str], alpha: float) -> dict[str, Any] | None:
        """Structure at this finding's own places that its physics cannot produce (issue 10).

        Called after selection with ``U`` (orthonormal basis of the whitened model) and
        ``e`` (its residual): for a per-reading effect the model *without* its readings'
        terms, for any other the model with it. Returns where that structure is (a dict
        for ``unexplained``'s ``where``) or None. Default: an input-only term must leave
        the same residual at every visit of the same reference direction
        (:func:`~calibration.discrepancy.effects.structure.visits_differ`); others: None.
        """
        if not self.input_only:
            return None
        from calibration.discrepancy.effects.structure import visits_differ

        found = visits_differ(pb, U, e, list(where.get("positions") or []), axes, alpha)
        if found is None:
            return None
        return {**found, "why": (f"{self.effect_id} is a function of the specific force, but "
                                 "the residual differs between visits of the same reference "
                                 "direction (it depends on something else, e.g. the previous "
                                 "position)")}

    def shape_after_turn(self, pb: Any, U: np.ndarray, e: np.ndarray, axes: list[str],
                         alpha: float) -> dict[str, Any] | None:
        """Structure at this named finding's places that its shape does not follow, judged
        after the turn check (``diagnose._turned_or_bent``: a finding that only turns the
        reference is reported as a table turn first), with ``U``, ``e`` the model with the
        term. Returns where (as :meth:`misses`) or None. Default: None."""
        return None

    def not_told_from(self, pb: Any, U: np.ndarray, e: np.ndarray, X: np.ndarray,
                         theta: float, alpha: float) -> tuple[list[str], str]:
        """Declared confusers this accepted term cannot be told from here whatever the fits
        say, and why (issue 22): one with no regressor of its own (``observable`` False)
        whose physics explains the term's evidence as well, or one whose regressor is, by
        this recording's design, the term's own at ``theta`` (where the better fit of one
        says nothing of the cause).

        Called at the term's stage with ``U``, ``e`` the model without it and ``X`` its
        lifted, unweighted columns. Non-empty: the term stays in the model (it removes the
        structure) but is reported not separable from them (by_fit.as_not_separable).
        Default: none.
        """
        return [], ""

    # --- words ------------------------------------------------------------
    def parameters(self, coef: np.ndarray, se: np.ndarray, theta: float,
                   ctx: DesignContext) -> tuple[dict[str, float], dict[str, float]]:
        raise NotImplementedError

    def axes(self, coef: np.ndarray, se: np.ndarray) -> list[str]:
        """Axes whose per-axis coefficient is clearly non-zero (≥ 3 σ), default: 3 per-axis cols."""
        k = coef.size
        if k % 3 == 0:
            z = np.abs(coef / np.where(se > 0, se, np.inf)).reshape(-1, 3)
            hit = [AXES[a] for a in range(3) if np.max(z[:, a]) >= 3.0]
            return hit or [AXES[int(np.argmax(np.max(z, axis=0)))]]
        return list(AXES)

    def stated_axes(self, pb: Any, coef: np.ndarray, se: np.ndarray,
                    alpha: float) -> tuple[list[str], str]:
        """The axes a finding names, and a clause its sentence adds about them ("" none).

        Default: the axes its coefficients resolve (:meth:`axes`). An effect whose physics
        check judges it on other axes than those (``scale_nonlinearity``: a bend where the
        resolved axes hold too few input levels, issue 22) names the axes it was judged on
        and says why, so the finding states what the data showed.
        """
        return self.axes(coef, se), ""

    def sentence(self, params: dict[str, float], sd: dict[str, float], axes: list[str],
                 ctx: DesignContext | None = None) -> str:
        """One plain sentence; ``ctx`` lets it say only what this recording can show."""
        return f"{self.effect_id}: " + ", ".join(_pm(k, params, sd) for k in params)

    def test_name(self) -> str:
        """The statistic named in a finding's ``evidence``."""
        if self.per_reading:
            return "leave-one-reading-out statistic, max over readings, min-p over candidates"
        # The replicates are said once, in the diagnosis' "null" (diagnose.null_method):
        # sign flips of the residual for these families, not a parametric bootstrap.
        if self.continuous:
            return (f"score test profiled over {self.theta_name} (grid, then refined), "
                    "min-p over candidates (bootstrap)")
        return ("score test after projecting out the model, min-p over candidates "
                "(bootstrap)")

    # --- model-file extension ----------------------------------------------
    def extension_fields(self, params: Mapping[str, float]) -> dict[str, Any]:
        """The term's fields in g-based SI units (default: the finding's parameters as is)."""
        return {"parameters": dict(params)}

    def extension_term_g(self, spec: Mapping[str, Any], a: np.ndarray) -> np.ndarray | None:
        """(N,3) extra raw output (g) at input ``a``; None: ``compensate`` has not the context
        it needs (time, the die temperature) and the term is identity there."""
        return None


def how_told_apart(a: CatalogueEffect, b: CatalogueEffect) -> str:
    """The text of either module for the pair, or the generic statement."""
    for one, other in ((a, b), (b, a)):
        for cid, text in one.told_apart:
            if cid == other.effect_id:
                return text
    return "compared by their p-values after projection"


def vec3(spec: Mapping[str, Any], key: str) -> np.ndarray:
    """A model-file field given as one value or one per axis, as (3,)."""
    return np.broadcast_to(np.asarray(spec.get(key, 0.0), float), (3,))


def per_axis(ctx: DesignContext, col: np.ndarray) -> np.ndarray:
    """(N,) column → (N,3,3): the same column acting on each axis separately."""
    out = np.zeros((ctx.n, 3, 3))
    for a in range(3):
        out[:, a, a] = col
    return out


def _pm(name: str, params: dict[str, float], sd: dict[str, float]) -> str:
    v = params[name]
    s = sd.get(name)
    return f"{name} = {v:.3g} ± {s:.2g}" if s is not None else f"{name} = {v:.3g}"


def fmt_pm(v: float, s: float, unit: str) -> str:
    digits = 0 if abs(s) >= 1 else 2
    return f"{v:.{digits}f} ± {s:.{digits}f} {unit}"


def axis_params(prefix: str, unit: str, coef: np.ndarray, se: np.ndarray, scale: float
                ) -> tuple[dict[str, float], dict[str, float]]:
    """Per-axis parameters ``{prefix}_{x|y|z}_{unit}`` from three coefficients (g-based)."""
    p = {f"{prefix}_{AXES[a]}_{unit}": float(coef[a] * scale) for a in range(3)}
    s = {f"{prefix}_{AXES[a]}_{unit}": float(se[a] * scale) for a in range(3)}
    return p, s
