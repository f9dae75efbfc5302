"""Simulated warm-up logs: a board kept still while its die warms (PX4/ArduPilot style).

Raw samples at ``rate_hz`` (one row per sample, no ``sd_*``), the die temperature
approaching its final value exponentially, each axis' bias a quadratic in temperature,
white noise per sample and an optionally quantised temperature channel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.recording import Recording
from simulators.truth import SensorTruth


@dataclass
class WarmupTruth:
    up: np.ndarray  # (3,) unit vector of gravity's reaction in the sensor frame
    bias0_g: np.ndarray  # (3,) bias at t_ref_c
    tempco_g_per_c: np.ndarray  # (3,) first-order bias coefficient
    tempco2_g_per_c2: np.ndarray  # (3,) second-order
    t_ref_c: float

    def bias_g(self, temperature_c: np.ndarray) -> np.ndarray:
        d = np.asarray(temperature_c, float)[:, None] - self.t_ref_c
        return self.bias0_g + self.tempco_g_per_c * d + self.tempco2_g_per_c2 * d**2


def warmup_log(*, seconds: float = 200.0, rate_hz: float = 500.0, t_start_c: float = -18.7,
               t_end_c: float = -13.3, tau_s: float = 80.0, noise_g: float = 1e-3,
               quantum_c: float | None = 0.06, up: tuple[float, float, float] = (0, 0, 1),
               segments: list[tuple[float, tuple[float, float, float]]] | None = None,
               sensor: SensorTruth | None = None, reference: bool = False,
               seed: int = 0) -> tuple[Recording, WarmupTruth]:
    """A raw-sample warm-up log and its truth.

    ``segments``: [(start_s, up), ...] changes the orientation at those times (a hand
    turning the board); default one orientation ``up`` throughout. ``sensor``: the
    twin's sensor (simulators/truth.py: full SFEM, every parameter cubic in the die
    temperature, its channel offset) instead of the bias-only truth; the returned
    WarmupTruth then describes nothing (the sensor is the truth). ``reference``: add
    ``ref_x/ref_y/ref_z``, the true direction of gravity's reaction (a fixture with
    known faces). See :func:`cycled` for orientations visited in turn.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    final = t_end_c + (t_end_c - t_start_c) * np.exp(-seconds / tau_s) / (
        1 - np.exp(-seconds / tau_s))
    temp = final - (final - t_start_c) * np.exp(-t / tau_s)
    truth = WarmupTruth(
        up=np.asarray(up, float) / np.linalg.norm(up),
        bias0_g=np.array([4e-3, -2e-3, 6e-3]),
        tempco_g_per_c=np.array([1.5e-4, -0.8e-4, 2.5e-4]),
        tempco2_g_per_c2=np.array([4e-6, 2e-6, -6e-6]),
        t_ref_c=-16.0,
    )
    ups = np.tile(truth.up, (t.size, 1))
    for start_s, u in segments or []:
        ups[t >= start_s] = np.asarray(u, float) / np.linalg.norm(u)
    if sensor is None:
        raw = ups + truth.bias_g(temp) + rng.normal(0.0, noise_g, (t.size, 3))
        read_c = temp + rng.normal(0.0, 0.01, t.size)
    else:
        raw = sensor.ideal_raw_g(ups, temp) + rng.normal(0.0, noise_g, (t.size, 3))
        read_c = temp + sensor.temp_offset_c + rng.normal(0.0, 0.01, t.size)
    if quantum_c:
        read_c = np.round(read_c / quantum_c) * quantum_c
    cols = {"t_s": t, "sensor_c": read_c, "ax": raw[:, 0], "ay": raw[:, 1], "az": raw[:, 2]}
    if reference:
        cols.update({"ref_x": ups[:, 0], "ref_y": ups[:, 1], "ref_z": ups[:, 2]})
    rec = Recording.from_columns(cols, path="warmup.csv")
    return rec, truth


def cycled(ups: list[tuple[float, float, float]], seconds: float, dwell_s: float
           ) -> list[tuple[float, tuple[float, float, float]]]:
    """``segments`` for :func:`warmup_log`: the orientations ``ups`` in turn, ``dwell_s``
    each, over ``seconds`` (a hand turning the board while it warms, so that every
    orientation sees the whole temperature range)."""
    starts = np.arange(0.0, seconds, dwell_s)
    return [(float(t0), ups[i % len(ups)]) for i, t0 in enumerate(starts)]
