"""A 1 °C temperature channel rebuilt from its transitions: RMS error against the die.

    .venv/bin/python -m benchmarks.bench_temperature_dequantise

Four die traces over 30 min (an exponential warm-up; an under-damped heater whose peak
and trough turn inside a 1 °C step; a 450-s rest inside a step, then a heating; a
heating then a natural cooling), read at 50 Hz with white noise of 0, 0.02 and 0.1 °C,
rounded to 1 °C and averaged into 1-s and 5-s capture means (what ``calibrate`` reads).
Per case: the RMS error against the true capture-mean die temperature of the step
values as read and of :func:`calibration.temperature_dequantise.dequantise`'s rebuild,
each less its mean (a constant offset is harmless to a warm-up's bias change), and the
rebuild's largest error. The step values' RMS is LSB/√12 = 0.29 °C for a clean channel.
``--spans``: per case instead, the spans the rebuild reports as unresolved (a rest or a
turn inside one step: kind and step), the share of the readings inside them, and the
rebuild's RMS error inside and outside them (two more traces that have none: a steady
ramp and the exponential warm-up cut before it slows).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from calibration.temperature_dequantise import dequantise  # noqa: E402

RATE_HZ = 50.0
DURATION_S = 1800.0


def exponential(t: np.ndarray) -> np.ndarray:
    """An exponential warm-up, 20.3 → 35.3 °C with τ 400 s."""
    return 20.3 + 15.0 * (1.0 - np.exp(-t / 400.0))


def overshoot(t: np.ndarray) -> np.ndarray:
    """An under-damped heater (ζ 0.35): a peak and a trough inside one level each."""
    wn, zeta = 2.5 / 300.0, 0.35
    wd = wn * np.sqrt(1 - zeta**2)
    return 20.0 + 8.0 * (1 - np.exp(-zeta * wn * t) * (
        np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t)))


def rest_heat_rest(t: np.ndarray) -> np.ndarray:
    """A flat stretch inside a step (20.3 °C for 450 s), a heating, a flat end."""
    return 20.3 + 10.0 * (1.0 - np.exp(-np.clip(t - 450.0, 0.0, None) / 300.0))


def heat_cool(t: np.ndarray) -> np.ndarray:
    """Heating for 1000 s (τ 400 s), then a natural cooling (τ 600 s)."""
    top = 20.0 + 15.0 * (1.0 - np.exp(-1000.0 / 400.0))
    return np.where(t < 1000.0, 20.0 + 15.0 * (1.0 - np.exp(-t / 400.0)),
                    20.0 + (top - 20.0) * np.exp(-(t - 1000.0) / 600.0))


# the die traces of this benchmark and of tests/calibration/test_temperature_dequantise.py
PROFILES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "exponential warm-up": exponential,
    "overshoot (2 turns)": overshoot,
    "rest, heat, rest": rest_heat_rest,
    "heat, then cool": heat_cool,
}


def _captures(profile: Callable[[np.ndarray], np.ndarray], noise_c: float, block_s: float,
              seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A whole-degree channel reading ``profile`` with ``noise_c``, as ``block_s`` capture
    means: (time s, reading °C, die °C, samples)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)
    die = profile(t)
    read = np.round(die + rng.normal(0.0, noise_c, t.size))
    k = np.floor(t / block_s).astype(int)
    n = np.bincount(k)
    return np.bincount(k, t) / n, np.bincount(k, read) / n, np.bincount(k, die) / n, n


def case(profile: Callable[[np.ndarray], np.ndarray], noise_c: float, block_s: float,
         seed: int = 0) -> tuple[float, float, float, int, int]:
    """(step RMS, rebuilt RMS, rebuilt max |error|, transitions, turning points), °C."""
    tc, rc, dc, n = _captures(profile, noise_c, block_s, seed)
    dq = dequantise(tc, rc)
    e0, e1 = rc - dc, dq.temperature_c - dc
    e0, e1 = e0 - e0.mean(), e1 - e1.mean()
    return (float(np.sqrt(np.mean(e0**2))), float(np.sqrt(np.mean(e1**2))),
            float(np.max(np.abs(e1))), dq.transitions, dq.turning_points)


def linear_ramp(t: np.ndarray) -> np.ndarray:
    """A steady heating, 20.3 °C + 1 °C every 2 min: never stops, never turns."""
    return 20.3 + t / 120.0


def cut_exponential(t: np.ndarray) -> np.ndarray:
    """The exponential warm-up's first 1000 s spread over 30 min: still moving at its end."""
    return exponential(t * 1000.0 / DURATION_S)


def spans_case(profile: Callable[[np.ndarray], np.ndarray], noise_c: float, block_s: float,
               seed: int = 0) -> tuple[str, float, float, float]:
    """(spans "kind step; …", share of readings inside, rebuilt RMS inside, outside), °C."""
    tc, rc, dc, n = _captures(profile, noise_c, block_s, seed)
    dq = dequantise(tc, rc, n)
    inside = dq.unresolved_mask(tc)
    e = dq.temperature_c - dc
    e = e - e.mean()

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")

    said = "; ".join(f"{s.kind} {s.level_c:g}" for s in dq.unresolved) or "none"
    return said, float(np.mean(inside)), rms(e[inside]), rms(e[~inside])


def main() -> int:
    if "--spans" in sys.argv[1:]:
        print("| die trace | channel noise °C | capture s | unresolved spans (kind, step °C) | "
              "share of readings | rebuilt RMS inside | rebuilt RMS outside |")
        print("|---|---|---|---|---|---|---|")
        traces = {**PROFILES, "steady ramp": linear_ramp, "exponential, cut": cut_exponential}
        for name, profile in traces.items():
            for noise in (0.0, 0.02, 0.1):
                for block in (1.0, 5.0):
                    said, share, r_in, r_out = spans_case(profile, noise, block)
                    print(f"| {name} | {noise:g} | {block:g} | {said} | {share:.2f} | "
                          f"{r_in:.3f} | {r_out:.3f} |")
        return 0
    print("| die trace | channel noise °C | capture s | step values RMS | rebuilt RMS | "
          "rebuilt max | transitions | turning points |")
    print("|---|---|---|---|---|---|---|---|")
    for name, profile in PROFILES.items():
        for noise in (0.0, 0.02, 0.1):
            for block in (1.0, 5.0):
                s, r, m, n, turns = case(profile, noise, block)
                print(f"| {name} | {noise:g} | {block:g} | {s:.3f} | {r:.3f} | {m:.3f} | "
                      f"{n} | {turns} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
