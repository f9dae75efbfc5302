"""dT/dt's noise on a rebuilt temperature: the rebuild's own error, measured by redoing it.

The rate check of a warm-up (:func:`calibration.warmup._rate_check`) reads dT/dt over the
shortest window whose noise is small against the rate it must resolve. A channel's white
noise is modelled by :func:`calibration.temperature_conditioning.temperature_noise_c`
from the readings' second differences. A temperature rebuilt from a coarse channel
(:mod:`calibration.temperature_dequantise`) is smooth: its second differences say nothing
of its error, which is not white but slow, largest where the die turns inside a step, and
it would be taken for a noiseless channel. Its error in dT/dt is measured here the way
:func:`~calibration.temperature_conditioning.rate_noise_c_per_min` measures white
noise's, by running the method on draws (a fixed seed), with the rebuilt trace standing
for the die:

* **crossings**: the trace read again as the channel would read it, each capture the mean
  of :data:`SUBSAMPLES` readings over its duration rounded to the lattice shifted by a
  random fraction of an LSB (where the thresholds fall against the die's path is what
  decides the rebuild's error), and rebuilt again;
* **dither**: the trace read again through a quantiser with the channel's noise (σ as
  estimated, ``samples`` readings per capture) and rebuilt with the same window and σ.

The noise is the RMS over captures and draws of the redone rebuild's dT/dt less the
trace's own, over the window asked for.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from calibration.series_memo import memo_by_value
from calibration.temperature_conditioning import (
    temperature_rate_c_per_min,
    temperature_rates_c_per_min,
)
from calibration.temperature_dequantise import Dequantised, dequantise_uncached
from calibration.temperature_dither import inverse_level, smoother_matrix

DRAWS = 6
SUBSAMPLES = 10


def rebuild_rate_noise(t_s: np.ndarray, dq: Dequantised, samples: np.ndarray | None = None
                       ) -> Callable[[float], float]:
    """window_s ↦ the RMS error (°C/min) of dT/dt read over that window from ``dq``'s
    rebuilt temperature (module docstring); 0 for a channel used as read.

    A function of the times, the rebuilt trace, its LSB and dither and the samples alone
    (the draws' seed is fixed): computed once per distinct series
    (:mod:`calibration.series_memo`), so refits of one log's temperatures redo no draw."""
    t = np.asarray(t_s, float)
    trace = np.asarray(dq.temperature_c, float)
    return _rebuild_rate_noise(t, trace, float(dq.lsb_c), float(dq.dither_lsb),
                               float(dq.window_s),
                               None if samples is None else np.asarray(samples, float))


@memo_by_value
def _rebuild_rate_noise(t: np.ndarray, trace: np.ndarray, q: float, dither_lsb: float,
                        smooth_s: float, samples: np.ndarray | None
                        ) -> Callable[[float], float]:
    """:func:`rebuild_rate_noise` on the rebuilt trace's values: ``q`` its LSB (0: not
    rebuilt), ``dither_lsb`` and ``smooth_s`` the dithered regime's noise and window."""
    ok = np.isfinite(t) & np.isfinite(trace)
    if q <= 0 or ok.sum() < 4:
        return lambda window_s: 0.0
    t, trace = t[ok], trace[ok]
    rng = np.random.default_rng(0)
    draws: list[np.ndarray] = []
    if dither_lsb > 0:
        n = (np.full(t.size, 50.0) if samples is None
             else np.clip(np.nan_to_num(samples[ok], nan=1.0), 1, 2000))
        H = smoother_matrix(t, smooth_s)
        z = trace / q
        for _ in range(DRAWS):
            # each capture's mean of n noisy readings, rounded: its level and the binomial
            # scatter of the share one level up, drawn exactly (reading k or k+1 or beyond)
            reads = np.array([np.mean(np.round(zi + rng.normal(0.0, dither_lsb, int(ni))))
                              for zi, ni in zip(z, n, strict=True)])
            draws.append(q * inverse_level(H @ reads, dither_lsb))
    else:
        d = float(np.median(np.diff(t)))
        offsets = (np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5
        sub = np.interp((t[:, None] + d * offsets[None, :]).ravel(), t, trace)
        for _ in range(DRAWS):
            shift = rng.uniform(-0.5, 0.5) * q
            reads = (np.round((sub + shift) / q) * q - shift).reshape(t.size, SUBSAMPLES)
            again = dequantise_uncached(t, reads.mean(axis=1))
            draws.append(again.temperature_c)
    cache: dict[float, float] = {}

    def noise(window_s: float) -> float:
        if window_s not in cache:
            own = temperature_rate_c_per_min(t, trace, window_s)
            sq = [np.mean((rate - own) ** 2)
                  for rate in temperature_rates_c_per_min(t, np.stack(draws), window_s)]
            cache[window_s] = float(np.sqrt(np.mean(sq)))
        return cache[window_s]

    return noise
