"""Former name of Eq. 1 with a parameter vector per reading; the model is written once in
:mod:`calibration.sfem`, whose functions take one vector (12,) or one per reading (N,12).

Kept so that callers not yet moved to :mod:`calibration.sfem` (``calibration/fit.py``,
``calibration/thermal.py``) keep working; new code calls :mod:`calibration.sfem`.
"""

from __future__ import annotations

from calibration.sfem import forward, forward_jacobian
from calibration.sfem import matrix_from_vector as matrices

__all__ = ["forward", "forward_jacobian", "matrices"]
