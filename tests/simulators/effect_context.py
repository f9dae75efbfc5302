"""A twin effect's reading context (``simulators.truth.Context``) for effect tests."""

from __future__ import annotations

import numpy as np

from simulators.truth import Context


def ctx_for(ref: np.ndarray, step_s: float = 60.0, **kw: object) -> Context:
    """One reading per row of ``ref`` (n, 3) g, ``step_s`` apart, die and air −40…60 °C,
    at rest, one session, heating; ``kw`` replaces any field."""
    N = ref.shape[0]
    base = dict(t_s=np.arange(N) * step_s, die_c=np.linspace(-40, 60, N),
                air_c=np.linspace(-40, 60, N), die_rate_c_per_s=np.zeros(N), ref_g=ref,
                step=np.zeros(N, int), direction=np.zeros(N, int), session=np.zeros(N, int),
                n_samples=np.full(N, 200.0), vib_sd_g=np.zeros(N), omega_rad_s=None)
    base.update(kw)
    return Context(**base)  # type: ignore[arg-type]
