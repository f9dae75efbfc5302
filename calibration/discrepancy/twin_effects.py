"""The catalogue effects a twin carries (docs/diagnosis.md §10).

``twin fit`` diagnoses the recording it fits and keeps, of what the diagnosis named, the
effects whose coefficients mean the same in any recording of the sensor
(``CatalogueEffect.twin_carries``: a nonlinearity, a hysteresis, a rate or vibration
sensitivity, a drift). Each is stored as the diagnosis fitted it: its effect id, its
nonlinear parameter θ, and its coefficients on the effect's own regressors
(``diagnose.term_coefficients``), beside the readable parameters the simulator builds its
counterpart from (``simulators.effects.to_truth_effects``). Its raw output at the readings
of any recording is then ``regressors(ctx, θ) @ coef`` (:func:`effects_raw_g`), one
evaluation for the twin's base fit and for ``diagnose --against``.

Why the base is refitted without them: the base model fitted with an effect present absorbs
the part of it that looks like a bias, a scale or a thermal coefficient; adding the whole
effect on top would count that part twice, in the simulated campaign and in the prediction
``--against`` holds fixed. So the twin's base is fitted to the recording less the carried
effects' output (:func:`without_effects`), and a recording compared with the twin is taken
less the same output first.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from calibration.discrepancy.context import DesignContext, base_context
from calibration.discrepancy.effects import BY_ID
from calibration.errors import CalibrationError, ModelFileError
from calibration.recording import Recording

RAW_COLUMNS = ("ax", "ay", "az")


def carried_effects(diag: Any) -> tuple[list[dict[str, Any]], list[dict[str, str]]]:
    """(effects the twin carries, findings it leaves out with why) of a diagnosis.

    Every finding is one or the other: ``unexplained`` and ``not_identifiable`` name no
    effect to carry, and are listed as left out so the report says the twin does not
    reproduce that structure.
    """
    from calibration.discrepancy.diagnose import term_coefficients

    coef_of = {t.key: (t, c, s) for t, c, s in term_coefficients(diag)}
    carried: list[dict[str, Any]] = []
    omitted: list[dict[str, str]] = []
    for f in diag.findings:
        eff = BY_ID.get(f.effect)
        if eff is None:
            axes = "/".join(f.axes) if f.axes else "?"
            omitted.append({"effect": f.effect,
                            "why": f"no catalogue term names this structure (axis {axes}): "
                                   "the twin does not reproduce it"})
            continue
        keys = f.term_keys
        if not eff.twin_carries or len(keys) != 1 or next(iter(keys)) not in coef_of:
            omitted.append({"effect": f.effect, "why": eff.twin_omitted})
            continue
        term, coef, sd = coef_of[next(iter(keys))]
        carried.append({
            "effect": f.effect,
            "theta": None if math.isnan(term.theta) else float(term.theta),
            "coef": [float(v) for v in coef],
            "coef_sd": [float(v) for v in sd],
            "parameters": dict(f.parameters),
            "parameter_sd": dict(f.parameter_sd),
            "explanation": f.explanation,
            "source": "soakcal diagnose",
        })
    return carried, omitted


def check_effects(effects: list[Any]) -> None:
    """Refuse a twin's ``effects`` list that cannot be evaluated (names the entry)."""
    for i, e in enumerate(effects):
        eid = e.get("effect") if isinstance(e, dict) else None
        eff = BY_ID.get(eid) if isinstance(eid, str) else None
        if eff is None or not eff.twin_carries:
            kinds = ", ".join(sorted(k for k, v in BY_ID.items() if v.twin_carries))
            raise ModelFileError(f"effects[{i}]: {eid!r} is not an effect a twin carries "
                                 f"({kinds})")
        coef = e.get("coef")
        if (not isinstance(coef, list) or not coef
                or not all(isinstance(v, int | float) and math.isfinite(v) for v in coef)):
            raise ModelFileError(f"effects[{i}] ({eid}): coef must be a non-empty list of numbers")
        theta = e.get("theta")
        if theta is not None and not (isinstance(theta, int | float) and math.isfinite(theta)):
            raise ModelFileError(f"effects[{i}] ({eid}): theta must be a number or null")


def context_of(rec: Recording, input_g: np.ndarray | None = None) -> DesignContext:
    """The design context the effects' regressors are evaluated in for ``rec``.

    ``input_g``: the specific force at each reading for the input-dependent effects (the
    references in reference mode, the default; in norm mode the readings stand in for it,
    within the sensor's scale and bias: a second-order change of a µg-scale effect).
    """
    mode = "reference" if rec.has_reference else "norm"
    if input_g is None:
        input_g = rec.ref_g if rec.has_reference else rec.raw_g
    return base_context(rec, mode, np.asarray(input_g, float))


def theta_of(effect: dict[str, Any]) -> float:
    """A carried effect's nonlinear parameter θ (nan for a linear effect: ``null``)."""
    return float("nan") if effect.get("theta") is None else float(effect["theta"])


def effects_design(effects: list[dict[str, Any]], ctx: DesignContext) -> np.ndarray:
    """(N, 3, K) raw output (g) per unit coefficient of the carried effects, side by side in
    the order of :func:`coefficients`."""
    blocks = []
    for i, e in enumerate(effects):
        eff = BY_ID[e["effect"]]
        theta = theta_of(e)
        try:
            X = eff.regressors(ctx, theta)  # (N, 3, k): raw output per unit coefficient
        except (AssertionError, ValueError, TypeError, IndexError) as exc:
            # What the effect reads is missing here (a vibration's sd_* columns): say so.
            why = eff.identifiable(ctx)[1] or str(exc)
            raise CalibrationError(f"the twin's {e['effect']} cannot be evaluated on this "
                                   f"recording: {why}") from exc
        if X.shape[-1] != len(e["coef"]):
            raise ModelFileError(f"effects[{i}] ({e['effect']}): {len(e['coef'])} "
                                 f"coefficient(s), its regressors have {X.shape[-1]}")
        blocks.append(X)
    return np.concatenate(blocks, axis=2) if blocks else np.zeros((ctx.n, 3, 0))


def coefficients(effects: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """The carried coefficients and their standard errors, concatenated (0 sd if absent)."""
    c = [float(v) for e in effects for v in e["coef"]]
    s = [float(v) for e in effects for v in (e.get("coef_sd") or [0.0] * len(e["coef"]))]
    return np.asarray(c), np.asarray(s)


def effects_raw_g(effects: list[dict[str, Any]], ctx: DesignContext) -> np.ndarray:
    """(N, 3) raw output (g) the carried effects add at the readings of ``ctx``."""
    return effects_design(effects, ctx) @ coefficients(effects)[0]


def without_effects(rec: Recording, effects: list[dict[str, Any]],
                    input_g: np.ndarray | None = None) -> Recording:
    """``rec`` with the carried effects' raw output taken out of ``ax``, ``ay``, ``az``
    (``input_g``: :func:`context_of`)."""
    if not effects:
        return rec
    return less_raw(rec, effects_raw_g(effects, context_of(rec, input_g)))


def less_raw(rec: Recording, delta_g: np.ndarray) -> Recording:
    """``rec`` with ``delta_g`` (N, 3) taken out of ``ax``, ``ay``, ``az``; the same recording
    otherwise (header, path, notes), without its text rows, which no longer match."""
    cols = dict(rec.columns)
    for a, c in enumerate(RAW_COLUMNS):
        cols[c] = np.asarray(cols[c], float) - delta_g[:, a]
    return replace(rec, columns=cols, cells=None)


def changed(effects: list[dict[str, Any]], delta: np.ndarray, sd: np.ndarray,
            z_min: float, ctx: DesignContext) -> list[str]:
    """Per carried effect, the parameters that moved (|z| ≥ ``z_min``, the smallest of the
    significant coefficients'), here against the twin's: "scale_nonlinearity k2_x_ug_per_g2
    169 ± 2 here, 152 ± 2 in the twin"."""
    out, i = [], 0
    for e in effects:
        k = len(e["coef"])
        eff = BY_ID[e["effect"]]
        theta = theta_of(e)
        c_twin = np.asarray(e["coef"], float)
        s_twin = np.asarray(e.get("coef_sd") or [0.0] * k, float)
        here, s_here = eff.parameters(c_twin + delta[i:i + k], sd[i:i + k], theta, ctx)
        twin, s_tw = eff.parameters(c_twin, s_twin, theta, ctx)
        moved = []
        for key, v in here.items():
            s = float(np.hypot(s_here[key], s_tw[key]))
            if s > 0 and abs(v - twin[key]) / s >= z_min - 1e-9:
                moved.append(f"{key} {v:.4g} ± {s_here[key]:.2g} here, {twin[key]:.4g} ± "
                             f"{s_tw[key]:.2g} in the twin")
        if moved:
            out.append(f"the twin's {e['effect']} differs: " + "; ".join(moved))
        i += k
    return out


def summary(effects: list[dict[str, Any]]) -> str:
    """"scale_nonlinearity, thermal_hysteresis" (or "none")."""
    return ", ".join(e["effect"] for e in effects) or "none"
