"""``scale_nonlinearity``: own-axis a² and a³ terms (effects.md).

Regressors per axis: ``a_i²`` and ``a_i³`` with a_i the input on axis i.
Axis-aligned positions alias a³ into scale (a³ = a) and a² partly into bias;
the absorbed fraction measures that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import AXES, DesignContext
from calibration.discrepancy.effects.base import UG, CatalogueEffect, fmt_pm, vec3


def own_powers(a: np.ndarray) -> np.ndarray:
    """(N,3) inputs → (N,3,6): ``a_i²`` (columns 0–2) and ``a_i³`` (3–5) on axis i."""
    out = np.zeros((a.shape[0], 3, 6))
    for i in range(3):
        out[:, i, i] = a[:, i] ** 2
        out[:, i, 3 + i] = a[:, i] ** 3
    return out


def scale_nonlinearity_g(a: np.ndarray, k2_per_g: np.ndarray, k3_per_g2: np.ndarray) -> np.ndarray:
    """Own-axis nonlinearity output change (N,3) g: ``K2_i a_i² + K3_i a_i³`` (effects.md).

    ``a`` (N,3) g, ``k2_per_g`` and ``k3_per_g2`` one value or (3,). The one place
    of this physics: the twin's truth effect and the model-file term
    (:meth:`ScaleNonlinearity.extension_term_g`) both call it.
    """
    k2 = np.broadcast_to(np.asarray(k2_per_g, float), (3,))
    k3 = np.broadcast_to(np.asarray(k3_per_g2, float), (3,))
    return own_powers(a) @ np.concatenate([k2, k3])


@dataclass(frozen=True)
class ScaleNonlinearity(CatalogueEffect):
    effect_id: str = "scale_nonlinearity"
    confusers: tuple[str, ...] = ("cross_coupling", "bias_drift")
    experiment: str = ("add oblique positions (e.g. the cube14 diagonals) so a³ and a² differ "
                       "from scale and bias")
    told_apart: tuple[tuple[str, str], ...] = (
        ("cross_coupling", "own-axis a², a³ versus products of two axes' inputs"),)
    writes_extension: bool = True
    extension_absorbed: bool = True
    input_only: bool = True

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return own_powers(ctx.input_g)

    def parameters(self, coef, se, theta, ctx):
        p, s = {}, {}
        for i, ax in enumerate(AXES):
            p[f"k2_{ax}_ug_per_g2"], s[f"k2_{ax}_ug_per_g2"] = coef[i] * UG, se[i] * UG
            p[f"k3_{ax}_ug_per_g3"], s[f"k3_{ax}_ug_per_g3"] = coef[3 + i] * UG, se[3 + i] * UG
        return ({k: float(v) for k, v in p.items()}, {k: float(v) for k, v in s.items()})

    def extension_fields(self, params):
        return {"k2_per_g": [params[f"k2_{a}_ug_per_g2"] * 1e-6 for a in AXES],
                "k3_per_g2": [params[f"k3_{a}_ug_per_g3"] * 1e-6 for a in AXES]}

    def extension_term_g(self, spec, a):
        return scale_nonlinearity_g(a, vec3(spec, "k2_per_g"), vec3(spec, "k3_per_g2"))

    def axes(self, coef, se):
        z = np.abs(coef / np.where(se > 0, se, np.inf)).reshape(2, 3)
        hit = [AXES[a] for a in range(3) if np.max(z[:, a]) >= 3.0]
        return hit or list(AXES)  # jointly significant, no axis resolved

    def sentence(self, params, sd, axes, ctx=None):
        z = {k: abs(v) / max(sd.get(k, 0.0), 1e-12) for k, v in params.items()}
        if max(z.values()) < 3.0:  # jointly significant, no single coefficient resolved
            top = max(z, key=z.__getitem__)
            unit = "µg/g²" if top.startswith("k2") else "µg/g³"
            return ("the outputs bend with their input (second/third-order terms, significant "
                    "together but not resolved coefficient by coefficient; largest "
                    f"{top} = {fmt_pm(params[top], sd[top], unit)})")
        parts = []
        for ax in axes:
            k2, s2 = params[f"k2_{ax}_ug_per_g2"], sd[f"k2_{ax}_ug_per_g2"]
            k3, s3 = params[f"k3_{ax}_ug_per_g3"], sd[f"k3_{ax}_ug_per_g3"]
            if abs(k2) / max(s2, 1e-12) >= abs(k3) / max(s3, 1e-12):
                parts.append(f"{ax} output grows with the square of its input: "
                             f"K2 = {fmt_pm(k2, s2, 'µg/g²')}")
            else:
                parts.append(f"{ax} output grows with the cube of its input: "
                             f"K3 = {fmt_pm(k3, s3, 'µg/g³')}")
        return "; ".join(parts)
