"""Registry of extension terms a model may carry beyond the base SFEM-cubic (issue 5).

A model document lists extensions as ``"extensions": [{"kind": "...", ...}, ...]``.
:meth:`ThermalModel.compensate` applies each listed extension, in order, after
the base model::

    calibrated = apply_fn(spec, raw_g, temperature_c, calibrated)

``spec`` is the extension's JSON object (its own parameters), ``raw_g`` (N,3)
the raw readings, ``temperature_c`` (N,) the thermal-model temperature (NaN
when unknown), ``calibrated`` (N,3) the output so far. The function returns
the new (N,3) calibrated specific force in g and must not modify its inputs.

Modules that define extension kinds call :func:`register_extension` at import;
:func:`load_builtin_extensions` imports the known ones so a model loaded by the
service or CLI can be applied.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from calibration.errors import CalibrationError

ApplyFn = Callable[[Mapping[str, Any], np.ndarray, np.ndarray, np.ndarray], np.ndarray]

_REGISTRY: dict[str, ApplyFn] = {}
# Modules that register extension kinds when imported (filled in by issue 5).
BUILTIN_MODULES: tuple[str, ...] = ("calibration.discrepancy.extensions",)


def register_extension(kind: str, apply_fn: ApplyFn) -> None:
    """Make ``kind`` applicable by :meth:`ThermalModel.compensate` (re-registering replaces)."""
    if not kind or not isinstance(kind, str):
        raise ValueError("extension kind must be a non-empty string")
    _REGISTRY[kind] = apply_fn


def registered_kinds() -> tuple[str, ...]:
    return tuple(sorted(_REGISTRY))


def get_extension(kind: str) -> ApplyFn:
    if kind not in _REGISTRY:
        load_builtin_extensions()
    try:
        return _REGISTRY[kind]
    except KeyError:
        known = ", ".join(registered_kinds()) or "none registered"
        raise CalibrationError(
            f"model extension kind {kind!r} is not known to this soakcal (known: {known})"
        ) from None


def load_builtin_extensions() -> None:
    """Import the modules that register extension kinds; missing ones are skipped."""
    for name in BUILTIN_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:
            continue


def apply_extensions(
    specs: list[dict[str, Any]],
    raw_g: np.ndarray,
    temperature_c: np.ndarray,
    calibrated_g: np.ndarray,
) -> np.ndarray:
    """Apply each extension of ``specs`` in order (see module docstring)."""
    out = calibrated_g
    for spec in specs:
        fn = get_extension(str(spec.get("kind", "")))
        out = np.asarray(fn(spec, raw_g, temperature_c, out), dtype=float)
        if out.shape != calibrated_g.shape:
            raise CalibrationError(
                f"extension {spec.get('kind')!r} returned shape {out.shape}, "
                f"expected {calibrated_g.shape}"
            )
    return out
