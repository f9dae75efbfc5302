"""A plateau design for the families' null tests: K plateaus of PER readings, per axis a
cubic in a normalised temperature as the base model (whitened: unit noise)."""

import numpy as np

from calibration.discrepancy import stats


def plateau_layout(k: int, per: int):
    """(n readings, plateau of each reading, reading of each entry, axis of each entry,
    orthonormal basis of the base model) for ``k`` plateaus of ``per`` readings."""
    n = k * per
    step = np.repeat(np.arange(k), per)
    t = np.linspace(-1.0, 1.0, k)[step] + 0.01 * np.tile(np.linspace(-1, 1, per), k)
    row = np.repeat(np.arange(n), 3)
    axis = np.tile(np.arange(3), n)
    X0 = np.zeros((3 * n, 12))  # per axis a cubic in t: the base model
    for a in range(3):
        X0[axis == a, 4 * a:4 * a + 4] = np.vander(t, 4, increasing=True)
    return n, step, row, axis, stats.orthonormal_basis(X0)
