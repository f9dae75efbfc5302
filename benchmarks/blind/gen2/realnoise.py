"""Noise of the second generator, drawn from the shared real recordings (not from a model).

Three pools, each standardised to unit sd per axis, read at benchmark time from the
directory given by ``--realdata`` (or ``SOAKCAL_REALDATA``):

* ``sensor``: an ADXL355 at rest (OpenAXES log, the 35 s before the first move), its mean
  removed per axis: the sensor's own sample noise, with its real spectrum and tails;
* ``vibration``: a 449 s static MPU-6050 recording (tomisuarez2), minus a 10 s moving mean:
  a real bench's disturbance above 0.1 Hz, zero mean (it is *not* rectified); its slow part
  does not average down within a capture, so means scatter more than sd/√n says;
* ``placement``: the same recording's 3 s window means about their slow trend: the
  heavy-ish shape of a re-seating error, scaled to an angle per visit.

Samples are drawn as contiguous blocks (a capture of n samples is n consecutive pool
samples), so the correlation within a capture is the recording's, not white.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

OPENAXES = "openaxes-adxl355/log_imu9_2022-06-22_22-13-55.csv"
MPU_STATIC = "tomisuarez2-mpu6050/example_data_tinit_calc.csv"
REST_S = 35.0  # OpenAXES: 40 s initial rest; the first 35 s are surely still
FS_HZ = 100.0


class RealDataMissing(RuntimeError):
    """The shared real recordings are not where the flag says."""


@dataclass(frozen=True)
class NoisePools:
    sensor: np.ndarray  # (Ns, 3) unit sd per axis
    vibration: np.ndarray  # (Nv, 3) unit sd per axis
    placement: np.ndarray  # (Np,) unit sd

    def block(self, rng: np.random.Generator, pool: str, n: int) -> np.ndarray:
        """n consecutive samples (n, 3) from a random start, axes from a random permutation."""
        src = getattr(self, pool)
        i = int(rng.integers(0, len(src) - n))
        return src[i:i + n][:, rng.permutation(3)] * rng.choice([-1.0, 1.0], 3)

    def mean_variance(self, pool: str, n: int, draws: int = 400, seed: int = 0) -> float:
        """Variance of the mean of n consecutive unit-sd samples (1/n if white)."""
        rng = np.random.default_rng(seed)
        m = np.array([self.block(rng, pool, n).mean(0) for _ in range(draws)])
        return float(np.mean(m**2))


def realdata_dir(arg: str | None) -> Path:
    d = arg or os.environ.get("SOAKCAL_REALDATA")
    if not d:
        raise RealDataMissing("no real recordings given: pass --realdata DIR (the shared real "
                              "recordings) or set SOAKCAL_REALDATA")
    p = Path(d)
    for rel in (OPENAXES, MPU_STATIC):
        if not (p / rel).is_file():
            raise RealDataMissing(f"{p / rel}: not found; --realdata must name the directory of "
                                  "the shared real recordings")
    return p


def _unit(x: np.ndarray) -> np.ndarray:
    x = x - x.mean(0)
    return x / x.std(0)


def load_pools(directory: Path) -> NoisePools:
    ox = np.genfromtxt(directory / OPENAXES, delimiter=";", names=True,
                       usecols=("TIME", "ACCEL_ADXL355_0", "ACCEL_ADXL355_1", "ACCEL_ADXL355_2"))
    t = (ox["TIME"] - ox["TIME"][0]) * 1e-6
    rest = np.column_stack([ox[f"ACCEL_ADXL355_{i}"] for i in range(3)])[t < REST_S]
    mpu = np.loadtxt(directory / MPU_STATIC, delimiter=",", skiprows=5)[:, :3]
    k = int(10 * FS_HZ)  # 10 s moving mean: what stays is the bench's disturbance > 0.1 Hz
    trend = np.apply_along_axis(lambda c: np.convolve(c, np.ones(k) / k, mode="same"), 0, mpu)
    vib = (mpu - trend)[k:-k]
    w = 3 * k
    win = mpu[: len(mpu) // w * w].reshape(-1, w, 3).mean(1)
    slow = np.apply_along_axis(lambda c: np.convolve(c, np.ones(9) / 9, mode="same"), 0, win)
    place = _unit((win - slow)[4:-4]).ravel()
    return NoisePools(sensor=_unit(rest), vibration=_unit(vib), placement=place / place.std())
