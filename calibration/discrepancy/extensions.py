"""Model-file extension terms written by ``diagnose`` and applied by ``soakcal compensate``.

Registered with :mod:`calibration.extensions` at import (``BUILTIN_MODULES``).
Each term removes, from the calibrated output, the extra raw output the
finding describes, mapped through the base model's matrix (≈ identity to
first order: corrections are µg-scale, so they are applied in output space).

Kinds (JSON object ``{"kind": ..., ...}``, parameters in g-based SI units):

* ``discrepancy.scale_nonlinearity``: ``k2_per_g`` [3], ``k3_per_g2`` [3]
* ``discrepancy.cross_coupling``: ``k_xy_per_g``, ``k_xz_per_g``, ``k_yz_per_g``
* ``discrepancy.thermal_hysteresis``: ``h_g`` [3], ``direction`` (+1/−1, the leg to correct)
* ``discrepancy.bias_drift``: ``rate_g_per_h`` [3], ``t0_s`` (needs ``t_s``: not applied
  by compensate, which has no time; recorded for the twin)
* ``discrepancy.thermal_lag``: ``tau_s`` (informational: compensate should use the die
  temperature; the term documents the lag)

Terms that need context compensate does not have are identity there and say so.
Each catalogue effect owns its term (``extension_fields``, ``extension_term_g``,
:mod:`calibration.discrepancy.effects.base`); this module only writes and registers
them, so no effect id is named here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.discrepancy.effects import ALL_EFFECTS
from calibration.discrepancy.effects.base import CatalogueEffect
from calibration.extensions import register_extension

PREFIX = "discrepancy."


def _input(calibrated: np.ndarray) -> np.ndarray:
    return calibrated  # why: the calibrated output is the input a to first order


def _absorbed(spec: Mapping[str, Any], a: np.ndarray, temperature_c: np.ndarray) -> np.ndarray:
    """The part of the term the base model already absorbed (affine in a, cubic in T).

    Why: the base model was fitted with the term present, so its bias/scale took
    the term's best affine-in-input approximation; subtracting the whole term
    would count that part twice.
    """
    ab = spec.get("absorbed")
    if not ab:
        return np.zeros_like(a)
    coef = np.asarray(ab["coef"], float)  # (3 axes, 4 inputs (1, a), degree+1)
    T = np.nan_to_num(np.asarray(temperature_c, float), nan=float(ab["t_mid_c"]))
    t = (T - float(ab["t_mid_c"])) / float(ab["t_half_c"])
    P = np.column_stack([t**p for p in range(coef.shape[2])])
    u = np.column_stack([np.ones(a.shape[0]), a])
    return np.einsum("nj,ajp,np->na", u, coef, P)


def applier(eff: CatalogueEffect):
    """The ``compensate`` function of an effect's term: remove what the base did not absorb.

    Effects without an input-only term (``extension_term_g`` None: they need time or the die
    temperature) are identity there and say so in the module docstring.
    """
    def apply(spec, raw_g, temperature_c, calibrated):
        a = _input(calibrated)
        term = eff.extension_term_g(spec, a)
        if term is None:
            return calibrated.copy()
        return calibrated - (term - _absorbed(spec, a, temperature_c))
    return apply


EXTENDING: dict[str, CatalogueEffect] = {
    PREFIX + e.effect_id: e for e in ALL_EFFECTS if e.writes_extension}
KINDS = {kind: applier(eff) for kind, eff in EXTENDING.items()}
for _kind, _fn in KINDS.items():
    register_extension(_kind, _fn)


def extension_specs(diag: Any) -> list[dict[str, Any]]:
    """JSON extension objects for a :class:`~calibration.discrepancy.Diagnosis`'s findings."""
    out: list[dict[str, Any]] = []
    for f in diag.findings:
        eff = EXTENDING.get(PREFIX + f.effect)
        if eff is None:
            continue
        spec: dict[str, Any] = {"kind": PREFIX + f.effect, "source": "soakcal diagnose",
                                "explanation": f.explanation}
        spec.update(eff.extension_fields(f.parameters))
        if eff.extension_absorbed:
            _add_absorbed(spec, diag, eff)
        out.append(spec)
    return out


def _add_absorbed(spec: dict[str, Any], diag: Any, eff: CatalogueEffect) -> None:
    """Weighted projection of the term on the base design (reference mode), stored per axis."""
    pb = getattr(diag, "problem", None)
    if pb is None or pb.mode != "reference":
        return
    n = pb.ctx.n
    contrib = eff.extension_term_g(spec, pb.ctx.input_g).ravel()
    k = pb.X0.shape[1] // 3
    Xw = pb.X0 * pb.w[:, None]
    beta = np.linalg.lstsq(Xw, contrib * pb.w, rcond=None)[0]
    coef = beta.reshape(3, 4, k // 4)
    spec["absorbed"] = {"t_mid_c": pb.t_mid_c, "t_half_c": pb.t_half_c,
                        "coef": coef.tolist(), "n_rows": n}


def write_extended_model(diag: Any, base_model_path: str, out_path: str) -> None:
    """Copy a model file and append the diagnosis' extension terms to its ``extensions``."""
    from calibration.model_file import load_model, save_model

    model = load_model(base_model_path)
    model.extensions = list(model.extensions) + extension_specs(diag)
    save_model(out_path, model)
