"""One capture from its raw samples for gen3 (issue 22): white noise at the sensor's noise
density, optionally a heavy-tailed error of the capture's mean (Student-t, ν 4–10, with the
same σ), slow zero-mean vibration (inflates the scatter; its mean error stays within what
sd/√n states and is unbiased: no rectification), quantisation of the raw samples."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ODRS_HZ = (62.5, 125.0, 250.0, 500.0, 1000.0)
RAW_LSBS_G = (3.9e-6, 2.5e-4)


@dataclass(frozen=True)
class Vibration:
    """Two sinusoids: one along a fixed direction (the three axes move together), one
    independent per axis; ``rms_g`` is the case's level, scaled per plateau."""

    rms_g: float
    direction: np.ndarray  # (3,) unit
    common_share: float  # of the variance
    freq_common_hz: float
    freq_axes_hz: np.ndarray  # (3,)


@dataclass(frozen=True)
class NoiseSpec:
    odr_hz: float
    n: int
    density_g: np.ndarray  # (3,) g/√Hz
    nu: float | None  # heavy-tailed capture mean when set
    vibration: Vibration | None
    raw_lsb_g: float | None

    @property
    def sample_sigma_g(self) -> np.ndarray:
        """The white per-sample σ (noise bandwidth ODR/2, docs/effects.md's figures)."""
        return self.density_g * np.sqrt(self.odr_hz / 2.0)

    @property
    def window_s(self) -> float:
        return self.n / self.odr_hz


def _vibration_freq(rng: np.random.Generator, odr_hz: float, n: int, size: int) -> np.ndarray:
    """Frequencies with at least max(3, √n/π) cycles per window (so the RMS error the
    vibration leaves in the mean, ≤ rms/(π·cycles), stays below rms/√n) and below 0.45·ODR
    (no aliasing into a slower apparent motion)."""
    window = n / odr_hz
    lo = max(3.0, np.sqrt(n) / np.pi) / window
    hi = 0.45 * odr_hz
    return np.exp(rng.uniform(np.log(lo), np.log(max(hi, lo * 1.01)), size))


def draw_noise(rng: np.random.Generator, *, heavy: bool, vibration: bool,
               quantised: bool) -> NoiseSpec:
    """ODR 62.5–1000 Hz, n 20–400 samples, density 20–30 µg/√Hz per axis; the three
    optional features as asked."""
    odr = float(rng.choice(ODRS_HZ))
    n = int(rng.integers(20, 401))
    vib = None
    if vibration:
        vib = Vibration(rms_g=float(rng.uniform(0.2e-3, 2e-3)),
                        direction=_unit(rng), common_share=float(rng.uniform(0.3, 1.0)),
                        freq_common_hz=float(_vibration_freq(rng, odr, n, 1)[0]),
                        freq_axes_hz=_vibration_freq(rng, odr, n, 3))
    return NoiseSpec(odr_hz=odr, n=n, density_g=rng.uniform(20e-6, 30e-6, 3),
                     nu=float(rng.uniform(4.0, 10.0)) if heavy else None, vibration=vib,
                     raw_lsb_g=float(rng.choice(RAW_LSBS_G)) if quantised else None)


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def vibration_samples(rng: np.random.Generator, vib: Vibration, level: float,
                      t_s: np.ndarray) -> np.ndarray:
    """(n, 3) zero-mean vibration of RMS ``vib.rms_g·level`` per axis, random phases."""
    rms = vib.rms_g * level
    amp_c = rms * np.sqrt(2.0 * vib.common_share)
    amp_a = rms * np.sqrt(2.0 * (1.0 - vib.common_share))
    common = amp_c * np.sin(2 * np.pi * vib.freq_common_hz * t_s + rng.uniform(0, 2 * np.pi))
    axes = amp_a * np.sin(2 * np.pi * np.outer(t_s, vib.freq_axes_hz)
                          + rng.uniform(0, 2 * np.pi, 3))
    return common[:, None] * vib.direction[None, :] + axes


def capture(rng: np.random.Generator, spec: NoiseSpec, true_g: np.ndarray,
            vib_level: float) -> tuple[np.ndarray, np.ndarray]:
    """The capture's (mean, sd) in g from ``spec.n`` raw samples about ``true_g``."""
    n = spec.n
    white = rng.standard_normal((n, 3)) * spec.sample_sigma_g
    if spec.nu is not None:
        # keep the samples' scatter, replace the mean's Gaussian error by a Student-t one
        # of the same σ (σ/√n per axis)
        t = rng.standard_t(spec.nu, 3) * np.sqrt((spec.nu - 2.0) / spec.nu)
        white = white - white.mean(axis=0) + t * spec.sample_sigma_g / np.sqrt(n)
    samples = true_g + white
    if spec.vibration is not None:
        t_s = np.arange(n) / spec.odr_hz
        samples = samples + vibration_samples(rng, spec.vibration, vib_level, t_s)
    if spec.raw_lsb_g is not None:
        samples = np.round(samples / spec.raw_lsb_g) * spec.raw_lsb_g
    return samples.mean(axis=0), samples.std(axis=0, ddof=1)
