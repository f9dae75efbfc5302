"""``vibration_rectification``: an offset ∝ the within-window variance (effects.md).

Regressor per axis: the recorded ``sd_a²`` (g²). Without ``sd_*`` it cannot
be seen; when the vibration follows temperature the cubic absorbs it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import CatalogueEffect, axis_params, fmt_pm


def rectified_offset_g(sd_vib_g: np.ndarray, c_per_g: np.ndarray) -> np.ndarray:
    """Vibration-rectification output change (N,3) g: ``c_i × σ²`` (effects.md).

    ``sd_vib_g`` is the vibration in g rms, one per reading (N,) acting on every
    axis (the twin's rig vibration) or per axis (N,3) (the recorded ``sd_*``);
    ``c_per_g`` one value or (3,).
    """
    sd = np.asarray(sd_vib_g, float)
    c = np.broadcast_to(np.asarray(c_per_g, float), (3,))
    return (sd**2 if sd.ndim == 2 else (sd**2)[:, None]) * c[None, :]


@dataclass(frozen=True)
class VibrationRectification(CatalogueEffect):
    effect_id: str = "vibration_rectification"
    confusers: tuple[str, ...] = ("bias_drift",)
    experiment: str = ("record sd_* and take positions with the chamber compressor on and off "
                       "at the same temperature")
    writes_extension: bool = True
    named_by_fit: bool = True

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        assert ctx.sd_g is not None
        out = np.zeros((ctx.n, 3, 3))
        for a in range(3):
            out[:, a, a] = ctx.sd_g[:, a] ** 2
        return out

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        if ctx.sd_g is None:
            return False, "no sd_* columns: the within-window variance is not recorded", \
                self.experiment
        return True, "", self.experiment

    def parameters(self, coef, se, theta, ctx):
        return axis_params("c", "per_g", coef, se, 1.0)

    def sentence(self, params, sd, axes, ctx=None):
        parts = [fmt_pm(params[f"c_{a}_per_g"], sd[f"c_{a}_per_g"], "per g") for a in axes]
        return (f"{'/'.join(axes)} output shifts with the vibration power seen in sd_*: "
                f"c = {', '.join(parts)}")
