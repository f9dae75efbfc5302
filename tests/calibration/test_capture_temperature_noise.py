"""A capture mean's temperature noise from its own raw samples, and the rate term it lets a
sparse warm-up resolve.

The warm-up's rate check reads dT/dt over the shortest window whose noise is small against
the rate it must resolve. Read from the capture means' own second differences, the noise of
captures 5 and 15 s apart (the fit half of alternate 10-s blocks) holds the warm-up's slope
(a second difference of uneven spacing does not cancel a line) and no window is quiet
enough; a capture's own samples say its mean's noise whatever the spacing, where they
average down as white noise.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from calibration import cli
from calibration.captures import capture_means, own_temperature_noise
from calibration.model_file import load_model
from calibration.recording import Recording, write_recording
from calibration.temperature_conditioning import (
    WHITE_TOLERANCE,
    capture_temperature_noise,
)

RATE_HZ = 10.0
TEMPCO_G_PER_C = np.array([12e-6, -6e-6, 20e-6])
CURVE_G_PER_C2 = np.array([0.4e-6, 0.3e-6, -0.5e-6])
RATE_GAIN_UG = np.array([40.0, -24.0, 32.0])  # per °C/min
SAMPLE_NOISE_G = 12e-6  # one sample's; 4 µg for a 1-s mean of 10
TEMP_NOISE_C = 0.05  # one sample's, white
WANDER_S = 2.0  # the correlated part's time constant


def _die(t_s: np.ndarray) -> np.ndarray:
    """Warms from 25 °C toward 45 °C (τ 10 min) for 15 min, then cools toward 30 °C."""
    hot = 25.0 + 20.0 * (1.0 - np.exp(-t_s / 600.0))
    at_off = 25.0 + 20.0 * (1.0 - np.exp(-900.0 / 600.0))
    return np.where(t_s <= 900.0, hot, 30.0 + (at_off - 30.0) * np.exp(-(t_s - 900.0) / 600.0))


def _raw_warmup(*, wander_c: float = 0.0, seed: int = 1) -> dict[str, np.ndarray]:
    """Raw samples at 10 Hz, as ``soakcal import`` writes them, of a rate-sensitive part at
    rest (z up); the channel white noise of TEMP_NOISE_C, plus a noise of SD ``wander_c``
    correlated over WANDER_S (first order), as the inclinometer channel's of issue 20 is
    (its 1-s means scatter 3.8x what its samples predict as white noise)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(1500 * RATE_HZ)) / RATE_HZ
    die = _die(t)
    d = die - 35.0
    acc = np.array([0.0, 0.0, 1.0]) + d[:, None] * TEMPCO_G_PER_C + d[:, None] ** 2 * CURVE_G_PER_C2
    acc = acc + 60.0 * np.gradient(die, t)[:, None] * RATE_GAIN_UG * 1e-6
    acc = acc + rng.normal(0.0, SAMPLE_NOISE_G, acc.shape)
    channel = die + rng.normal(0.0, TEMP_NOISE_C, t.size)
    if wander_c:
        rho = np.exp(-1.0 / (WANDER_S * RATE_HZ))
        kicks = rng.normal(0.0, wander_c * np.sqrt(1.0 - rho**2), t.size)
        wander = np.zeros(t.size)
        for i in range(1, t.size):
            wander[i] = rho * wander[i - 1] + kicks[i]
        channel = channel + wander
    return {"t_s": t, "sensor_c": channel, "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2],
            "n": np.ones(t.size)}


def _fit_blocks(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The held-out split's fit half: alternate 10-s blocks (two 5-s captures each)."""
    keep = (cols["t_s"] // 10) % 2 == 0
    return {k: v[keep] for k, v in cols.items()}


def _calibrate(tmp_path: Path, cols: dict[str, np.ndarray], capsys) -> tuple[dict, Path]:
    src, model = tmp_path / "raw.csv", tmp_path / "model.json"
    write_recording(src, cols)
    assert cli.run_calibrate(SimpleNamespace(recording=str(src), output=str(model),
                                             json=True)) == 0
    return json.loads(capsys.readouterr().out), model


def _heldout_rms_ug(tmp_path: Path, cols: dict[str, np.ndarray], model: Path) -> np.ndarray:
    """`compensate` of every sample: per axis, the RMS (µg) of the held-out blocks' 5-s
    means about the fit blocks' compensated mean."""
    src, out = tmp_path / "all.csv", tmp_path / "comp.csv"
    write_recording(src, cols)
    assert cli.run_compensate(SimpleNamespace(model=str(model), recording=str(src),
                                              output=str(out), extrapolate=True)) == 0
    with out.open() as f:
        comp = np.array([[float(r[c]) for c in ("cx", "cy", "cz")] for r in csv.DictReader(f)])
    t = cols["t_s"]
    fit = (t // 10) % 2 == 0
    five = (t // 5).astype(int)
    means = np.array([comp[five == h].mean(axis=0) for h in np.unique(five[~fit])])
    return np.sqrt(np.mean((means - comp[fit].mean(axis=0)) ** 2, axis=0)) * 1e6


def test_white_channel_noise_of_a_capture_mean_is_read_from_its_own_samples() -> None:
    rec = Recording.from_columns(_fit_blocks(_raw_warmup()))
    caps = capture_means(rec)
    noise = own_temperature_noise(rec, caps)
    assert noise is not None and noise.per_capture_c is not None
    assert noise.per_capture_c.shape == (len(caps.recording),)
    # a 5-s capture of 50 white samples: σ/√50, whatever the captures' spacing and the
    # warm-up's slope and curvature between them
    expected = TEMP_NOISE_C / np.sqrt(5 * RATE_HZ)
    assert abs(float(np.median(noise.per_capture_c)) / expected - 1.0) < 0.15
    assert noise.white_ratio < WHITE_TOLERANCE


def test_a_wandering_channel_is_not_credited_with_averaging() -> None:
    # 0.05 °C white samples plus 0.06 °C correlated over 2 s: the 1-s means scatter about
    # twice what 0.05/√10 predicts, so a capture's samples cannot say its mean's noise
    rec = Recording.from_columns(_fit_blocks(_raw_warmup(wander_c=0.06)))
    noise = own_temperature_noise(rec, capture_means(rec))
    assert noise is not None and noise.per_capture_c is None
    assert noise.white_ratio > WHITE_TOLERANCE
    assert "does not average down as white noise" in noise.said()


def test_a_quantised_channel_that_does_not_dither_is_not_credited() -> None:
    # 0.1 °C steps, no noise: the samples' second differences are mostly 0 and the capture
    # mean's rounding error does not average down
    t = np.arange(3000) / RATE_HZ
    temp = np.round((20.0 + t / 600.0) / 0.1) * 0.1
    group = (t // 5).astype(int)
    noise = capture_temperature_noise(t, temp, group)
    assert noise is not None and noise.per_capture_c is None


def test_a_sparse_raw_warmup_resolves_its_rate_term_from_the_captures_own_noise(
        tmp_path: Path, capsys) -> None:
    # The capture means' second differences on 5-s captures 5 and 15 s apart read the
    # heating's slope (about 0.3 °C) as noise and resolved no window: no rate term, and
    # the held-out 5-s means carried the part's 40 µg/(°C/min) (tens of µg).
    cols = _raw_warmup()
    doc, model_path = _calibrate(tmp_path, _fit_blocks(cols), capsys)
    check = doc["rate_identifiability"]
    assert check["tried"] is True, check
    assert "from each capture's own samples" in check["temperature_noise"]
    assert doc["rate_term"] is not None
    gain = np.asarray(load_model(model_path).temperature_rate["gain_ug_per_c_per_min"])
    np.testing.assert_allclose(gain[:, 0], RATE_GAIN_UG, atol=6.0)
    # held out through `compensate`: within twice a 5-s mean's noise (12 µg/√50 = 1.7 µg;
    # without the rate term 27 / 16 / 21 µg)
    assert np.all(_heldout_rms_ug(tmp_path, cols, model_path) < 3.5)


def test_a_sparse_raw_warmup_of_a_wandering_channel_says_which_noise_it_used(
        tmp_path: Path, capsys) -> None:
    cols = _fit_blocks(_raw_warmup(wander_c=0.06))
    doc, _ = _calibrate(tmp_path, cols, capsys)
    said = doc["rate_identifiability"]["temperature_noise"]
    assert said.startswith("from the capture means' second differences")
    assert "does not average down as white noise" in said
