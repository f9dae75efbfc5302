"""A warm-up model's capture means against their own noise: what no function of
temperature explains.

Held-out error (:mod:`calibration.warmup`) chooses among functions of temperature; it
cannot say that none of them explains the data. A board that tilts or settles, or a bias
that drifts with time, leaves the capture means scattered far beyond a capture mean's own
noise whatever the degree. :func:`scatter_check` measures that scatter per axis; the
warm-up fit refuses at degree 0 and notes it otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import chi2

# The chosen model's capture means must not scatter far beyond a capture mean's own noise
# (:func:`scatter_check`): per axis, the residual sum of squares over that noise² is a
# chi-square on the residual degrees of freedom if the model is right. An axis is "beyond
# the noise" when that chi-square passes its 1 − WANDER_ALPHA/3 quantile (three axes) AND
# the residual RMS is over WANDER_RATIO times the noise: a variance 9× the noise's, which
# an underestimate of the noise by even 40 % (a coloured noise, a short log's few second
# differences) does not reach, while a chi-square alone would call a 10 % underestimate
# significant on a long log.
WANDER_ALPHA = 1e-3
WANDER_RATIO = 3.0
# Second differences needed to estimate the noise of a capture mean.
MIN_NOISE_TRIPLES = 5

AXIS_NAMES = ("x", "y", "z")


@dataclass
class ScatterCheck:
    """How far a warm-up model leaves its capture means from it, against their noise
    (:func:`scatter_check`). Per axis x, y, z; g."""
    noise_g: np.ndarray  # a capture mean's noise (NaN: not determined)
    residual_rms_g: np.ndarray  # about the model, per residual degree of freedom
    beyond: np.ndarray  # bool: scattered beyond the noise (WANDER_ALPHA, WANDER_RATIO)
    dof: int
    not_judged: str | None = None  # why the scatter could not be judged

    @property
    def unexplained_g(self) -> np.ndarray:
        """The scatter the noise does not account for: √(residual² − noise²), ≥ 0."""
        return np.sqrt(np.clip(self.residual_rms_g ** 2 - self.noise_g ** 2, 0.0, None))

    def shown(self) -> str:
        """The axes beyond the noise, e.g. "y 5.14 mg RMS beyond a noise of 0.192 mg per
        capture mean" (3 significant digits: a twin's noise is 0.008 mg, a BMI270's 0.2)."""
        return ", ".join(
            f"{AXIS_NAMES[a]} {self.unexplained_g[a] * 1e3:.3g} mg RMS beyond a noise of "
            f"{self.noise_g[a] * 1e3:.3g} mg per capture mean"
            for a in np.flatnonzero(self.beyond))

    def unexplained_mg(self) -> dict[str, float]:
        """``report["unexplained_mg"]``: the axes beyond the noise only (empty: none)."""
        return {AXIS_NAMES[a]: round(float(self.unexplained_g[a]) * 1e3, 4)
                for a in np.flatnonzero(self.beyond)}

    def note(self, degree: int, no_rate_why: str | None) -> str | None:
        """The model's note: the scatter the kept model leaves (or that none was judged).
        ``no_rate_why``: why no rate term was fitted (None: one was)."""
        if self.not_judged:
            return f"the capture means' scatter about the model is not judged: {self.not_judged}"
        if not self.beyond.any():
            return None
        model = f"degree {degree}" + (" with a rate term" if no_rate_why is None else "")
        rate = ("" if no_rate_why is None else
                f", or a bias following dT/dt (a rate effect, a lagging channel) that no "
                f"rate term fits here: {no_rate_why}")
        return (f"the compensated capture means still wander beyond their noise, not as a "
                f"function of temperature: {self.shown()}; the {model} model is kept "
                f"(held-out error prefers it), but compensated readings keep this scatter "
                f"(a board that tilts or settles, a bias drifting with time{rate}); clamp "
                f"the board and let it settle before recording")

    def to_dict(self) -> dict[str, Any]:
        def mg(v: np.ndarray) -> list[float | None]:
            return [round(float(x) * 1e3, 4) if np.isfinite(x) else None for x in v]
        return {"noise_mg_xyz": mg(self.noise_g), "residual_rms_mg_xyz": mg(self.residual_rms_g),
                "unexplained_mg_xyz": mg(self.unexplained_g),
                "beyond_noise_xyz": [bool(b) for b in self.beyond], "dof": self.dof,
                "alpha": WANDER_ALPHA, "ratio": WANDER_RATIO, "not_judged": self.not_judged}


def scatter_check(t_s: np.ndarray, raw: np.ndarray, design: np.ndarray, x: np.ndarray,
                  labels: np.ndarray, degree: int, sigma_g: np.ndarray | None) -> ScatterCheck:
    """The chosen model's capture-mean residuals against a capture mean's noise.

    Per axis, if the model is right and the means' errors are independent with the noise
    σ (:func:`_capture_noise_g`), SS/σ² is chi-square on n − p degrees of freedom. An
    axis is beyond the noise when SS/σ² passes its 1 − :data:`WANDER_ALPHA`/3 quantile
    and the residual RMS exceeds :data:`WANDER_RATIO` σ. In-sample residuals: the model
    saw them, so this can only understate the scatter. With 2 or more orientations each
    has its own polynomial of the degree here: a scale that changes with temperature moves
    opposite faces oppositely (what :mod:`calibration.warmup_absolute` fits), and that is
    a function of temperature too, not a wander. ``design``: the model's own columns (the
    orientations' constants, x¹ … x^degree, the rate term's), at the captures."""
    k = int(labels.max()) + 1
    X = design
    if k > 1 and degree > 0:
        onehot = (labels[:, None] == np.arange(k)[None, :]).astype(float)
        powers = np.vander(x, degree + 1, increasing=True)[:, 1:]
        X = np.hstack([X, (onehot[:, 1:, None] * powers[:, None, :]).reshape(x.size, -1)])
    beta, *_ = np.linalg.lstsq(X, raw, rcond=None)
    res = raw - X @ beta
    dof = int(X.shape[0] - np.linalg.matrix_rank(X))
    noise, why = _capture_noise_g(t_s, raw, labels, sigma_g)
    rms = np.sqrt(np.sum(res ** 2, axis=0) / max(dof, 1))
    none = np.zeros(3, bool)
    if dof < 1:
        why = why or "no residual degree of freedom"
    if why:
        return ScatterCheck(noise, rms, none, dof, why)
    limit = float(chi2.ppf(1.0 - WANDER_ALPHA / 3.0, dof))
    beyond = (np.sum(res ** 2, axis=0) > limit * noise ** 2) & (rms > WANDER_RATIO * noise)
    return ScatterCheck(noise, rms, beyond, dof)


def _capture_noise_g(t_s: np.ndarray, raw: np.ndarray, labels: np.ndarray,
                     sigma_g: np.ndarray | None) -> tuple[np.ndarray, str | None]:
    """(3,) the noise of one capture mean, g, and why it could not be determined (None).

    From each orientation's capture means in time order: the middle of every three
    consecutive means less the straight line through its two neighbours, r, whose
    variance is σ²·(1 + w₀² + w₂²) for white errors (w the interpolation weights; 1.5 at
    equal spacing). A change that is linear over three captures cancels in it, so a
    slowly wandering channel (a tilt creeping over minutes, the bias following the
    temperature) does not inflate it, and it uses no temperature, so a quantised
    temperature channel does not enter. It measures the mean's own noise, whatever the
    samples' correlation (a sensor's digital filter makes its samples' sd/√n too small).
    Where the captures carry sd and n, σ is at least their RMS sd/√n: the smaller of two
    estimates of one noise is the likelier to be low by chance, and a low σ refuses."""
    parts: list[np.ndarray] = []
    for o in np.unique(labels):
        idx = np.flatnonzero(labels == o)
        idx = idx[np.argsort(t_s[idx], kind="stable")]
        if idx.size < 3:
            continue
        t, y = t_s[idx], raw[idx]
        span = t[2:] - t[:-2]
        w0 = np.where(span > 0, (t[2:] - t[1:-1]) / np.where(span > 0, span, 1.0), 0.5)
        w2 = 1.0 - w0
        r = y[1:-1] - (w0[:, None] * y[:-2] + w2[:, None] * y[2:])
        parts.append(r ** 2 / (1.0 + w0 ** 2 + w2 ** 2)[:, None])
    n_triples = sum(p.shape[0] for p in parts)
    if n_triples < MIN_NOISE_TRIPLES:
        return (np.full(3, np.nan),
                f"the noise of a capture mean cannot be estimated from {n_triples} run(s) "
                f"of three consecutive captures of one orientation ({MIN_NOISE_TRIPLES} "
                "needed)")
    noise = np.sqrt(np.mean(np.vstack(parts), axis=0))
    if sigma_g is not None:
        within = np.sqrt(np.nanmean(np.where(np.isfinite(sigma_g), sigma_g ** 2, np.nan),
                                    axis=0))
        noise = np.fmax(noise, within)
    if not np.all(np.isfinite(noise) & (noise > 0)):
        return noise, ("consecutive capture means are identical on an axis (a reading "
                       "quantised coarser than its noise): their noise is not known")
    return noise, None
