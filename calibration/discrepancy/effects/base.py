"""The one small interface every catalogue effect module implements (effects.md).

An effect module says how the physics would show in the raw output of each
reading (``regressors``: (N,3,k) g per unit parameter), over a grid of its
nonlinear parameter if it has one (``grid``: profile), whether a protocol can
reveal it at all (``identifiable``), and how to say what was found
(``parameters`` with uncertainties, ``sentence``). Whether the *base model*
absorbs it is measured, not declared: ``absorbed_fraction`` in
:mod:`calibration.discrepancy.stats`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import AXES, DesignContext

UG = 1e6  # g → µg


@dataclass(frozen=True)
class EffectModule:
    """Base: a linear effect with no nonlinear parameter. Subclasses override what differs."""

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

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        """Protocol-level check: (can this recording show it, why not, experiment that would)."""
        if self.needs_motion:
            return (False, "it acts only while the table rotates; every reading here is static",
                    self.experiment)
        return True, "", self.experiment

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

    def sentence(self, params: dict[str, float], sd: dict[str, float], axes: list[str]) -> str:
        return f"{self.effect_id}: " + ", ".join(_pm(k, params, sd) for k in params)


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
