"""The one call into the calibration core: evaluate a stored model document at a temperature.

Isolated so the API does not depend on the model file format's internals, and
so tests can substitute it.
"""

from __future__ import annotations

from typing import Any


class ModelUnavailable(RuntimeError):
    """The calibration core cannot evaluate models in this installation (HTTP 503)."""


def evaluate_model(
    doc: dict[str, Any], temperature_c: float, extrapolate: bool
) -> tuple[list[list[float]], list[float]]:
    """``(matrix 3x3, bias_g 3)`` of ``doc`` at ``temperature_c``.

    Raises ``calibration.errors.OutOfRange`` outside the valid range unless
    ``extrapolate``; ``ModelUnavailable`` if ``calibration.model_file`` is missing.
    """
    try:
        from calibration.model_file import load_model_dict
    except ImportError as exc:
        raise ModelUnavailable(f"calibration.model_file is not available: {exc}") from exc
    matrix, bias_g = load_model_dict(doc).coefficients_at(temperature_c, extrapolate=extrapolate)
    return _as_lists(matrix), [float(b) for b in _flat(bias_g)]


def _as_lists(matrix: Any) -> list[list[float]]:
    rows = matrix.tolist() if hasattr(matrix, "tolist") else matrix
    return [[float(v) for v in row] for row in rows]


def _flat(values: Any) -> list[Any]:
    return list(values.tolist() if hasattr(values, "tolist") else values)
