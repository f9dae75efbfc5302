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
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from calibration.extensions import register_extension

PREFIX = "discrepancy."


def _vec(spec: Mapping[str, Any], key: str) -> np.ndarray:
    return np.broadcast_to(np.asarray(spec.get(key, 0.0), float), (3,))


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


def term_scale_nonlinearity(spec: Mapping[str, Any], a: np.ndarray) -> np.ndarray:
    return _vec(spec, "k2_per_g") * a**2 + _vec(spec, "k3_per_g2") * a**3


def term_cross_coupling(spec: Mapping[str, Any], a: np.ndarray) -> np.ndarray:
    xy = float(spec.get("k_xy_per_g", 0.0)) * a[:, 0] * a[:, 1]
    xz = float(spec.get("k_xz_per_g", 0.0)) * a[:, 0] * a[:, 2]
    yz = float(spec.get("k_yz_per_g", 0.0)) * a[:, 1] * a[:, 2]
    return np.column_stack([xy + xz, xy + yz, xz + yz])


def apply_scale_nonlinearity(spec, raw_g, temperature_c, calibrated):
    a = _input(calibrated)
    return calibrated - (term_scale_nonlinearity(spec, a) - _absorbed(spec, a, temperature_c))


def apply_cross_coupling(spec, raw_g, temperature_c, calibrated):
    a = _input(calibrated)
    return calibrated - (term_cross_coupling(spec, a) - _absorbed(spec, a, temperature_c))


def apply_hysteresis(spec, raw_g, temperature_c, calibrated):
    d = float(spec.get("direction", 0.0))
    return calibrated - d * _vec(spec, "h_g")[None, :]


def apply_identity(spec, raw_g, temperature_c, calibrated):
    return calibrated.copy()


KINDS = {
    PREFIX + "scale_nonlinearity": apply_scale_nonlinearity,
    PREFIX + "cross_coupling": apply_cross_coupling,
    PREFIX + "thermal_hysteresis": apply_hysteresis,
    PREFIX + "bias_drift": apply_identity,
    PREFIX + "thermal_lag": apply_identity,
    PREFIX + "session_offset": apply_identity,
    PREFIX + "temperature_rate": apply_identity,
    PREFIX + "vibration_rectification": apply_identity,
}
for _kind, _fn in KINDS.items():
    register_extension(_kind, _fn)


def extension_specs(diag: Any) -> list[dict[str, Any]]:
    """JSON extension objects for a :class:`~calibration.discrepancy.Diagnosis`'s findings."""
    out: list[dict[str, Any]] = []
    for f in diag.findings:
        kind = PREFIX + f.effect
        if kind not in KINDS:
            continue
        p = f.parameters
        spec: dict[str, Any] = {"kind": kind, "source": "soakcal diagnose",
                                "explanation": f.explanation}
        ax = ("x", "y", "z")
        if f.effect == "scale_nonlinearity":
            spec["k2_per_g"] = [p[f"k2_{a}_ug_per_g2"] * 1e-6 for a in ax]
            spec["k3_per_g2"] = [p[f"k3_{a}_ug_per_g3"] * 1e-6 for a in ax]
            _add_absorbed(spec, diag, term_scale_nonlinearity)
        elif f.effect == "cross_coupling":
            for pair in ("xy", "xz", "yz"):
                spec[f"k_{pair}_per_g"] = p[f"k_{pair}_ug_per_g2"] * 1e-6
            _add_absorbed(spec, diag, term_cross_coupling)
        elif f.effect == "thermal_hysteresis":
            spec["h_g"] = [p[f"h_{a}_ug"] * 1e-6 for a in ax]
            spec["direction"] = 0.0  # set +1/−1 for the leg being compensated
        elif f.effect == "bias_drift":
            spec["rate_g_per_h"] = [p[f"rate_{a}_ug_per_h"] * 1e-6 for a in ax]
        elif f.effect == "thermal_lag":
            spec["tau_s"] = p["tau_s"]
        else:
            spec["parameters"] = dict(p)
        out.append(spec)
    return out


def _add_absorbed(spec: dict[str, Any], diag: Any, term) -> None:
    """Weighted projection of the term on the base design (reference mode), stored per axis."""
    pb = getattr(diag, "problem", None)
    if pb is None or pb.mode != "reference":
        return
    n = pb.ctx.n
    contrib = term(spec, pb.ctx.input_g).ravel()
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
