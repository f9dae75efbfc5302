"""Catalogue effects a static soak tumble cannot reveal: they only say so, and how to see them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.effects.base import CatalogueEffect


@dataclass(frozen=True)
class Unobservable(CatalogueEffect):
    """An effect declared not identifiable under this recording's protocol, with the reason."""

    why: str = ""
    observable: bool = False

    def regressors(self, ctx: DesignContext, theta: float) -> np.ndarray:
        return np.zeros((ctx.n, 3, 0))

    def identifiable(self, ctx: DesignContext) -> tuple[bool, str, str]:
        return False, self.why, self.experiment
