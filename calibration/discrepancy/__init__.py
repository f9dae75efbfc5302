"""Mismatch diagnosis (issue 5): locate what the base model leaves out, name it, model it, verify.

Method: docs/diagnosis.md. Entry point: :func:`diagnose`; ``diagnose_against``
(``against.py``) holds a model or twin fixed. ``write_diagnosis_figures`` is
imported lazily (matplotlib, which ``soakcal compensate`` does not need). The
twin counterparts of findings live with the simulator's effects
(``simulators.effects.to_truth_effects``): calibration/ never imports simulators/.
"""

from typing import Any

from calibration.discrepancy.diagnose import Diagnosis, Finding, diagnose

__all__ = ["Diagnosis", "Finding", "diagnose", "write_diagnosis_figures"]


def __getattr__(name: str) -> Any:
    if name == "write_diagnosis_figures":
        from calibration.discrepancy.report import write_diagnosis_figures

        return write_diagnosis_figures
    raise AttributeError(name)
