"""Errors of the calibration core, each naming what was wrong and what was expected."""

from __future__ import annotations


class CalibrationError(ValueError):
    """Base class for bad input to the calibration core."""


class RecordingError(CalibrationError):
    """A recording file is malformed; names the file, 1-based line and column."""

    def __init__(self, path: str, line: int | None, column: str | None, message: str) -> None:
        where = str(path)
        if line is not None:
            where += f":{line}"
        if column is not None:
            where += f": column '{column}'"
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.line = line
        self.column = column
        self.message = message


class OutOfRange(CalibrationError):
    """A temperature outside a model's valid range, without ``extrapolate``."""

    def __init__(self, temperature_c: float, valid_c: tuple[float, float]) -> None:
        super().__init__(
            f"temperature {temperature_c:.2f} °C is outside the calibrated range "
            f"[{valid_c[0]:.2f}, {valid_c[1]:.2f}] °C (pass extrapolate to use it anyway)"
        )
        self.temperature_c = temperature_c
        self.valid_c = valid_c


class NotIdentifiable(CalibrationError):
    """The data cannot determine the requested parameters (too few or degenerate positions)."""


class ModelFileError(CalibrationError):
    """A model JSON file is malformed or of an unknown version."""
