"""The versioned JSON model document (schema: ``docs/model-file.md``).

``{"format": "soakcal-model", "version": 2, "model_version": "sfem-cubic-1", ...}``

Version 2 adds ``temperature.compensation`` (how ``compensate`` conditions the
temperature by default) and ``temperature.streaming_filter`` (the causal filter
a streaming consumer applies); version 1 files are still read, and get the
same defaults (their calibrate conditioned temperature the same way).

:func:`dump_model_dict` / :func:`load_model_dict` convert a :class:`ThermalModel`
to and from the JSON-able dict the service stores and returns;
:func:`save_model` writes it atomically, :func:`load_model` reads a file.
Every rejection is a :class:`ModelFileError` naming the offending field.
NaN (a stderr that does not exist) is written as ``null``.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from calibration import sfem
from calibration.captures import CAPTURE_BLOCK_S
from calibration.errors import ModelFileError
from calibration.recording import atomic_write_text
from calibration.temperature_conditioning import (
    CAPTURE_MEAN_KIND,
    CAUSAL_KIND,
    CompensationConditioning,
    default_streaming_filter,
)
from calibration.thermal import MODEL_VERSION, StepParams, ThermalModel

FORMAT = "soakcal-model"
VERSION = 2
READABLE_VERSIONS = (1, 2)
MODES = ("reference", "norm", "warmup")

_Doc = TypeVar("_Doc")


# --- writing ------------------------------------------------------------------
def dump_model_dict(model: ThermalModel) -> dict[str, Any]:
    """The model as a JSON-able dict (format ``soakcal-model`` version 2)."""
    names = sfem.PARAM_NAMES
    d = model.degree
    phys = model.physical_coeffs()
    se = model.coeff_stderr if model.coeff_stderr is not None else np.full_like(model.coeffs,
                                                                                np.nan)
    return {
        "format": FORMAT,
        "version": VERSION,
        "model_version": model.model_version,
        "mode": model.mode,
        "method": model.method,
        "g_local": model.g_local,
        "parameters": list(names),
        "parameter_units": dict(zip(names, sfem.PARAM_UNITS, strict=True)),
        "identifiable": {n: bool(v) for n, v in zip(names, model.identifiable, strict=True)},
        "fitted": dict(model.fitted),
        "held": dict(model.held),
        "temperature": {
            "source": model.temperature_source,
            "conditioning": model.temperature_conditioning,
            "valid_c": None if model.valid_c is None else [float(v) for v in model.valid_c],
            "centre_c": model.t_centre_c,
            "scale_c": model.t_scale_c,
            "variable": "x = (T - centre_c) / scale_c",
            "compensation": conditioning_of(model).to_dict(),
            "streaming_filter": default_streaming_filter(conditioning_of(model).tau_s,
                                                         conditioning_of(model).jump_c),
            "rate": None if model.temperature_rate is None else dict(model.temperature_rate),
        },
        "polynomial": {
            "degree": d,
            "basis": "p(T) = sum_j coefficients[j] * x**j",
            "coefficients": {n: _floats(model.coeffs[k]) for k, n in enumerate(names)},
            "stderr": {n: _floats(se[k]) for k, n in enumerate(names)},
            "physical_basis": "p(T) = sum_j physical_coefficients[j] * (T - centre_c)**j",
            "physical_coefficients": {n: _floats(phys[k]) for k, n in enumerate(names)},
            "physical_units": {
                n: [u if j == 0 else f"{u}/degC^{j}" if j > 1 else f"{u}/degC"
                    for j in range(d + 1)]
                for n, u in zip(names, sfem.PARAM_UNITS, strict=True)
            },
        },
        "steps": [
            {
                "step": st.step,
                "temperature_c": _float(st.temperature_c),
                "positions": st.n_positions,
                "params": dict(zip(names, _floats(st.params), strict=True)),
                "stderr": dict(zip(names, _floats(st.stderr), strict=True)),
            }
            for st in model.steps
        ],
        "extensions": [dict(e) for e in model.extensions],
        "provenance": dict(model.provenance),
        "notes": list(model.notes),
    }


def conditioning_of(model: ThermalModel) -> CompensationConditioning:
    """How ``compensate`` conditions the temperature for this model by default: a soak
    model per step as calibrate did (the causal filter otherwise); a warm-up model at each
    capture's mean temperature, as :mod:`calibration.warmup` fitted it."""
    if model.mode == "warmup":
        return CompensationConditioning.for_warmup(CAPTURE_BLOCK_S)
    return CompensationConditioning()


def save_model(path: str | os.PathLike, model: ThermalModel) -> None:
    """Write the model JSON atomically (temp file + rename)."""
    text = json.dumps(dump_model_dict(model), indent=2, allow_nan=False) + "\n"
    atomic_write_text(path, text)


# --- reading ------------------------------------------------------------------
def load_model(path: str | os.PathLike) -> ThermalModel:
    """Read a model file; :class:`ModelFileError` names the file and the bad field."""
    return load_json_document(path, load_model_dict, "model")


def load_json_document(
    path: str | os.PathLike, from_dict: Callable[[Any], _Doc], what: str
) -> _Doc:
    """Read the JSON file at ``path`` and convert it with ``from_dict``.

    The one reader of soakcal's JSON documents (the model file here, the twin file in
    ``calibration/discrepancy/twin_file.py``): every failure -- missing, unreadable, not
    JSON, or refused by ``from_dict`` -- is a :class:`ModelFileError` that starts with the
    path; ``what`` names the document in the messages ("model", "model or twin").
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ModelFileError(f"{p}: {what} file not found") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{p}: not a JSON {what} file ({exc})") from None
    except OSError as exc:  # a directory, a permission problem
        raise ModelFileError(f"{p}: cannot read the {what} file ({exc.strerror or exc})") from None
    try:
        return from_dict(doc)
    except ModelFileError as exc:
        raise ModelFileError(f"{p}: {exc}") from None


def load_model_dict(doc: Any) -> ThermalModel:
    """Validate and convert a model document back into a :class:`ThermalModel`."""
    if not isinstance(doc, dict):
        raise ModelFileError("model document must be a JSON object")
    if doc.get("format") != FORMAT:
        raise _bad("format", f"expected {FORMAT!r}, got {doc.get('format')!r}")
    if doc.get("version") not in READABLE_VERSIONS or isinstance(doc.get("version"), bool):
        raise _bad("version", f"this soakcal reads versions {READABLE_VERSIONS}, "
                   f"got {doc.get('version')!r}")
    mv = doc.get("model_version")
    if mv != MODEL_VERSION:
        raise _bad("model_version", f"expected {MODEL_VERSION!r}, got {mv!r}")
    mode = doc.get("mode")
    if mode not in MODES:
        raise _bad("mode", f"expected one of {MODES}, got {mode!r}")
    names = sfem.PARAM_NAMES
    if doc.get("parameters") != list(names):
        raise _bad("parameters", f"expected {list(names)}")
    temp = _obj(doc, "temperature")
    valid = temp.get("valid_c")
    valid_c: tuple[float, float] | None = None
    if valid is not None:
        if not (isinstance(valid, list) and len(valid) == 2):
            raise _bad("temperature.valid_c", "expected null or [low, high]")
        lo, hi = (_num(v, "temperature.valid_c") for v in valid)
        if not lo <= hi:
            raise _bad("temperature.valid_c", f"low {lo} is above high {hi}")
        valid_c = (lo, hi)
    centre = _num(temp.get("centre_c"), "temperature.centre_c")
    scale = _num(temp.get("scale_c"), "temperature.scale_c")
    if scale <= 0:
        raise _bad("temperature.scale_c", f"must be positive, got {scale}")
    source = temp.get("source", "sensor_c")
    if source not in ("sensor_c", "chamber_c", "none"):
        raise _bad("temperature.source", f"expected sensor_c, chamber_c or none, got {source!r}")

    poly = _obj(doc, "polynomial")
    degree = poly.get("degree")
    if not isinstance(degree, int) or isinstance(degree, bool) or not 0 <= degree <= 10:
        raise _bad("polynomial.degree", f"expected an integer 0..10, got {degree!r}")
    coeffs = _param_table(poly, "coefficients", degree + 1, allow_null=False)
    stderr = _param_table(poly, "stderr", degree + 1, allow_null=True) if "stderr" in poly \
        else None

    ident_doc = doc.get("identifiable", {n: True for n in names})
    if not isinstance(ident_doc, dict) or any(not isinstance(ident_doc.get(n), bool)
                                              for n in names):
        raise _bad("identifiable", "expected an object of 12 booleans keyed by parameter")
    identifiable = np.array([ident_doc[n] for n in names])

    g_local = _num(doc.get("g_local", 1.0), "g_local")
    steps = [_step(s, i) for i, s in enumerate(_list(doc, "steps"))]
    exts = _list(doc, "extensions")
    for i, e in enumerate(exts):
        if not isinstance(e, dict) or not isinstance(e.get("kind"), str) or not e["kind"]:
            raise _bad(f"extensions[{i}].kind", "each extension needs a non-empty string 'kind'")
    prov = doc.get("provenance", {})
    if not isinstance(prov, dict):
        raise _bad("provenance", "expected an object")
    notes = doc.get("notes", [])
    if not isinstance(notes, list):
        raise _bad("notes", "expected a list of strings")
    load_conditioning_dict(doc)  # validated here so a bad document is refused at load
    fitted, held = (_reasons(doc, k) for k in ("fitted", "held"))
    method = doc.get("method", "per_step")
    if not isinstance(method, str):
        raise _bad("method", "expected a string")
    return ThermalModel(
        coeffs=coeffs,
        t_centre_c=centre,
        t_scale_c=scale,
        valid_c=valid_c,
        mode=mode,
        identifiable=identifiable,
        coeff_stderr=stderr,
        method=method,
        temperature_source=source,
        temperature_conditioning=str(temp.get("conditioning", "")),
        g_local=g_local,
        steps=steps,
        extensions=[dict(e) for e in exts],
        notes=[str(n) for n in notes],
        provenance=dict(prov),
        model_version=mv,
        fitted=fitted,
        held=held,
        temperature_rate=_rate_term(temp.get("rate")),
    )


def _reasons(doc: dict[str, Any], key: str) -> dict[str, str]:
    """``fitted``/``held``: parameter name → why (absent in files before they existed)."""
    obj = doc.get(key, {})
    if not isinstance(obj, dict) or any(
            k not in sfem.PARAM_NAMES or not isinstance(v, str) for k, v in obj.items()):
        raise _bad(key, "expected an object of parameter name -> reason (string)")
    return dict(obj)


def _rate_term(obj: Any) -> dict[str, Any] | None:
    """``temperature.rate``: null/absent, or a warm-up's k(T)·dT/dt term (per axis the gain's
    coefficients in x, and the window dT/dt is read over)."""
    if obj is None:
        return None
    if not isinstance(obj, dict):
        raise _bad("temperature.rate", "expected null or an object")
    gain = obj.get("gain_ug_per_c_per_min")
    field = "temperature.rate.gain_ug_per_c_per_min"
    if not (isinstance(gain, list) and len(gain) == 3 and all(
            isinstance(g, list) and g and len(g) == len(gain[0]) for g in gain)):
        raise _bad(field, "expected three equal, non-empty lists (X, Y, Z) of coefficients")
    for axis in gain:
        for v in axis:
            _num(v, field)
    if _num(obj.get("window_s"), "temperature.rate.window_s") <= 0:
        raise _bad("temperature.rate.window_s", "must be positive")
    return dict(obj)


def load_conditioning_dict(doc: dict[str, Any]) -> CompensationConditioning:
    """``temperature.compensation`` of a (validated) model document; defaults for version 1."""
    temp = doc.get("temperature") if isinstance(doc.get("temperature"), dict) else {}
    comp = temp.get("compensation")
    if comp is None:
        return CompensationConditioning()
    if not isinstance(comp, dict):
        raise _bad("temperature.compensation", "expected an object")
    per = comp.get("per_step", {})
    other = comp.get("otherwise", {})
    if not isinstance(per, dict) or not isinstance(other, dict):
        raise _bad("temperature.compensation", "expected objects 'per_step' and 'otherwise'")
    enabled = per.get("enabled", True)
    if not isinstance(enabled, bool):
        raise _bad("temperature.compensation.per_step.enabled", "expected a boolean")
    kind = other.get("kind", CAUSAL_KIND)
    if kind == CAPTURE_MEAN_KIND:
        block = _num(other.get("block_s"), "temperature.compensation.otherwise.block_s")
        if block <= 0:
            raise _bad("temperature.compensation.otherwise.block_s", "must be positive")
        return CompensationConditioning.for_warmup(block)
    if kind != CAUSAL_KIND:
        raise _bad("temperature.compensation.otherwise.kind",
                   f"expected {CAUSAL_KIND!r} or {CAPTURE_MEAN_KIND!r}, got {kind!r}")
    tau = _num(other.get("tau_s", 600.0), "temperature.compensation.otherwise.tau_s")
    jump = _num(other.get("jump_c", 1.0), "temperature.compensation.otherwise.jump_c")
    if tau <= 0 or jump <= 0:
        raise _bad("temperature.compensation.otherwise", "tau_s and jump_c must be positive")
    return CompensationConditioning(per_step=enabled, tau_s=tau, jump_c=jump)


def load_model_file(path: str | os.PathLike) -> tuple[ThermalModel, CompensationConditioning]:
    """:func:`load_model` plus the file's compensation conditioning."""
    p = Path(path)
    model = load_model(p)
    doc = json.loads(p.read_text(encoding="utf-8"))
    try:
        return model, load_conditioning_dict(doc)
    except ModelFileError as exc:
        raise ModelFileError(f"{p}: {exc}") from None


# --- helpers ------------------------------------------------------------------
def _bad(field: str, message: str) -> ModelFileError:
    return ModelFileError(f"model field '{field}': {message}")


def _obj(doc: dict[str, Any], key: str) -> dict[str, Any]:
    v = doc.get(key)
    if not isinstance(v, dict):
        raise _bad(key, "missing or not an object")
    return v


def _list(doc: dict[str, Any], key: str) -> list[Any]:
    v = doc.get(key, [])
    if not isinstance(v, list):
        raise _bad(key, "expected a list")
    return v


def _num(v: Any, field: str, *, allow_null: bool = False) -> float:
    if v is None and allow_null:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise _bad(field, f"expected a finite number, got {v!r}")
    return float(v)


def _param_table(obj: dict[str, Any], key: str, width: int, *, allow_null: bool) -> np.ndarray:
    table = obj.get(key)
    if not isinstance(table, dict):
        raise _bad(f"polynomial.{key}", "missing or not an object keyed by parameter")
    out = np.empty((sfem.N_PARAMS, width))
    for k, n in enumerate(sfem.PARAM_NAMES):
        row = table.get(n)
        field = f"polynomial.{key}.{n}"
        if not isinstance(row, list) or len(row) != width:
            raise _bad(field, f"expected a list of {width} numbers (degree + 1)")
        out[k] = [_num(v, field, allow_null=allow_null) for v in row]
    return out


def _step(s: Any, i: int) -> StepParams:
    where = f"steps[{i}]"
    if not isinstance(s, dict):
        raise _bad(where, "expected an object")
    params, stderr = s.get("params"), s.get("stderr", {})
    if not isinstance(params, dict) or not isinstance(stderr, dict):
        raise _bad(f"{where}.params", "expected objects keyed by parameter")
    p = np.array([_num(params.get(n), f"{where}.params.{n}") for n in sfem.PARAM_NAMES])
    se = np.array([_num(stderr.get(n), f"{where}.stderr.{n}", allow_null=True)
                   for n in sfem.PARAM_NAMES])
    step = s.get("step")
    if not isinstance(step, int) or isinstance(step, bool):
        raise _bad(f"{where}.step", f"expected an integer, got {step!r}")
    positions = s.get("positions", 0)
    if not isinstance(positions, int) or isinstance(positions, bool):
        raise _bad(f"{where}.positions", f"expected an integer, got {positions!r}")
    T = _num(s.get("temperature_c"), f"{where}.temperature_c", allow_null=True)
    return StepParams(step, T, positions, p, se)


def _float(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _floats(a: np.ndarray) -> list[float | None]:
    return [_float(float(v)) for v in np.asarray(a, float).ravel()]
