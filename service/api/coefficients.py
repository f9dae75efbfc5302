"""The one call into the calibration core: evaluate a stored model document at a temperature.

Isolated so the API does not depend on the model file format's internals, and
so tests can substitute it. Loading (validating and converting the JSON
document) and evaluating are separate steps so the API can keep loaded models
in a :class:`ModelCache`: a coefficient query then costs one polynomial
evaluation instead of a parse of the ~15 kB document.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any

DEFAULT_CACHE_ENTRIES = 1024  # a loaded cubic model is ~15 kB of Python objects


class ModelUnavailable(RuntimeError):
    """The calibration core cannot evaluate models in this installation (HTTP 503)."""


def load_model(doc: dict[str, Any]) -> Any:
    """The model document as an object :func:`evaluate` accepts.

    Raises ``calibration.errors.ModelFileError`` (a ``CalibrationError``) for a
    bad document; ``ModelUnavailable`` if ``calibration.model_file`` is missing.
    """
    try:
        from calibration.model_file import load_model_dict
    except ImportError as exc:
        raise ModelUnavailable(f"calibration.model_file is not available: {exc}") from exc
    return load_model_dict(doc)


def evaluate(
    model: Any, temperature_c: float, extrapolate: bool
) -> tuple[list[list[float]], list[float]]:
    """``(matrix 3x3, bias_g 3)`` of a loaded model at ``temperature_c``.

    Raises ``calibration.errors.OutOfRange`` outside the valid range unless ``extrapolate``.
    """
    matrix, bias_g = model.coefficients_at(temperature_c, extrapolate=extrapolate)
    return _as_lists(matrix), [float(b) for b in _flat(bias_g)]


class ModelCache:
    """Loaded models by calibration id, least recently used evicted; safe across threads.

    Keying by id alone is sound because a calibration row is never updated
    (``service.engine.store`` only inserts them) and ids are not reused while
    the row exists. One cache per app: each app has its own database.
    """

    def __init__(self, max_entries: int = DEFAULT_CACHE_ENTRIES) -> None:
        if max_entries < 1:
            raise ValueError(f"max_entries must be >= 1, got {max_entries}")
        self.max_entries = max_entries
        self._models: OrderedDict[int, Any] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, calibration_id: int) -> Any | None:
        """The loaded model of ``calibration_id``, or None if not cached."""
        with self._lock:
            model = self._models.get(calibration_id)
            if model is not None:
                self._models.move_to_end(calibration_id)
            return model

    def put(self, calibration_id: int, model: Any) -> None:
        with self._lock:
            self._models[calibration_id] = model
            self._models.move_to_end(calibration_id)
            while len(self._models) > self.max_entries:
                self._models.popitem(last=False)

    def __len__(self) -> int:
        with self._lock:
            return len(self._models)


def _as_lists(matrix: Any) -> list[list[float]]:
    rows = matrix.tolist() if hasattr(matrix, "tolist") else matrix
    return [[float(v) for v in row] for row in rows]


def _flat(values: Any) -> list[Any]:
    return list(values.tolist() if hasattr(values, "tolist") else values)
