"""Mismatch diagnosis (issue 5): locate what the base model leaves out, name it, model it, verify.

Method: docs/diagnosis.md. Entry point: :func:`diagnose`. ``to_truth_effects``
and ``write_diagnosis_figures`` are imported lazily (they pull in the
simulators and matplotlib, which ``soakcal compensate`` does not need).
"""

from typing import Any

from calibration.discrepancy.diagnose import Diagnosis, Finding, diagnose

__all__ = ["Diagnosis", "Finding", "diagnose", "to_truth_effects", "write_diagnosis_figures"]


def __getattr__(name: str) -> Any:
    if name == "to_truth_effects":
        from calibration.discrepancy.twin import to_truth_effects

        return to_truth_effects
    if name == "write_diagnosis_figures":
        from calibration.discrepancy.report import write_diagnosis_figures

        return write_diagnosis_figures
    raise AttributeError(name)
