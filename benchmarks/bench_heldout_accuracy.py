"""Held-out accuracy of the thermal model against the noise-limited oracle.

    .venv/bin/python benchmarks/bench_heldout_accuracy.py [--sensors 10] [--method joint]
                     [--orientations 60] [--temp-noise-c 0.1] [--soak-min 60]
                     [--row-temp-noise-c 0.1] [--conditioning raw|default|causal]

For each simulated ADXL355 (``SensorTruth.adxl355_typical(seed)``, datasheet
magnitudes, sensor-channel offset ±2 °C):

1. calibrate on a simulated −40…60 °C soak campaign (10 °C steps, seed Table 1,
   200 samples per position; the temperature channel's noise per raw sample
   ``--temp-noise-c``) with :func:`calibration.thermal.fit_campaign`;
2. simulate a separate verification run at −35, −5, 25, 55 °C (die), each in
   ``--orientations`` random orientations, with fresh noise;
3. compensate it with the model at each row's own ``sensor_c`` reading
   (``--conditioning raw``, the default here so earlier figures reproduce), or
   conditioned as ``soakcal compensate`` does by default (``default``: per
   step, the run having setpoints), or by the causal filter alone
   (``causal``: the run's step/setpoint columns withheld), or the channel's
   noise-free value (``truth``: what remains is the calibration's share);
4. compare the RMS vector error (calibrated − true specific force, µg) with the
   oracle: the sensor's *true* parameters at the true die temperature applied to
   the same readings -- the error left by the readings' noise alone.

Requirement: ratio model/oracle ≤ 1.15 (target 1.05), for the pooled RMS.
``--row-temp-noise-c`` adds white noise of that rms to every row's ``sensor_c``
of both the campaign and the verification run (a temperature channel read once
per reading, not averaged like the accelerometer): issue 11's "0.1 °C noisy
temperature channel"; its requirement is ratio ≤ 1.10 with the default commands.

Also, as the seed's Fig. 11 ("1346 µg/K → 37 µg/K"): a cooling run 60 → −40 °C
at one orientation (z up), |slope| of the output vs die temperature (µg/K,
vector of the three axis slopes), raw and compensated; median over sensors.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from calibration import sfem  # noqa: E402
from calibration.metrics import thermal_drift  # noqa: E402
from calibration.temperature_conditioning import (  # noqa: E402
    compensation_temperature,
    smooth_over_time,
)
from calibration.thermal import DEFAULT_METHOD, fit_campaign  # noqa: E402
from simulators.campaign_sim import RigPhysics, simulate_campaign, simulate_static_run  # noqa: E402
from simulators.truth import SensorTruth  # noqa: E402

HELDOUT_C = (-35.0, -5.0, 25.0, 55.0)
REQUIRED_RATIO = 1.15
TARGET_RATIO = 1.05


def random_orientations(n: int, rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def heldout_case(
    seed: int,
    method: str = DEFAULT_METHOD,
    *,
    orientations: int = 60,
    temp_noise_c: float = 0.1,
    soak_min: float = 60.0,
    samples_per_position: int = 200,
    physics: RigPhysics | None = None,
    extrapolate: bool = False,
    smooth_temperature_s: float = 0.0,
    row_temp_noise_c: float = 0.0,
    conditioning: str = "raw",
) -> dict[str, float]:
    """One sensor: squared-error sums of model and oracle on its verification run."""
    truth = SensorTruth.adxl355_typical(seed)
    truth.temp_noise_c = temp_noise_c
    rec = simulate_campaign(truth, seed=seed + 10_000, soak_min=soak_min, physics=physics,
                            samples_per_position=samples_per_position)
    noise_rng = np.random.default_rng(seed + 50_000)
    if row_temp_noise_c > 0:
        rec.columns["sensor_c"] = rec.columns["sensor_c"] + noise_rng.normal(
            0.0, row_temp_noise_c, len(rec))
    fit = fit_campaign(rec, method=method)  # type: ignore[arg-type]
    rng = np.random.default_rng(seed + 20_000)
    refs = np.vstack([random_orientations(orientations, rng) for _ in HELDOUT_C])
    die = np.repeat(HELDOUT_C, orientations)
    run = simulate_static_run(truth, refs, die, seed=seed + 30_000)
    raw = run.recording.raw_g
    if row_temp_noise_c > 0:
        run.recording.columns["sensor_c"] = run.recording.columns["sensor_c"] + \
            noise_rng.normal(0.0, row_temp_noise_c, len(run.recording))
    temp_c = run.recording.temperature_c()
    if conditioning in ("default", "causal"):
        vr = run.recording
        with_steps = conditioning == "default"
        temp_c, _ = compensation_temperature(
            vr.t_s, temp_c,
            vr.columns["step"] if with_steps and vr.has("step") else None,
            vr.columns["setpoint_c"] if with_steps and vr.has("setpoint_c") else None)
    elif conditioning == "truth":  # the channel without noise: what is left is calibration
        temp_c = die + truth.temp_offset_c
    if smooth_temperature_s > 0:
        temp_c = smooth_over_time(run.recording.t_s, temp_c, smooth_temperature_s)
    cal = fit.model.compensate(raw, temp_c, extrapolate=extrapolate)
    oracle = sfem.forward(truth.params_vector_at(die), raw)
    err_m = np.sum((cal - refs) ** 2, axis=1)
    err_o = np.sum((oracle - refs) ** 2, axis=1)
    out = {"seed": seed, "sse_model": float(err_m.sum()), "sse_oracle": float(err_o.sum()),
           "n": int(refs.shape[0])}
    for T in HELDOUT_C:
        m = die == T
        out[f"ratio_{T:g}"] = float(np.sqrt(err_m[m].sum() / err_o[m].sum()))
    # Seed Fig. 11: a cooling run at one orientation, 60 → −40 °C, drift before/after.
    die_cool = np.linspace(60.0, -40.0, 101)
    cool = simulate_static_run(truth, np.tile([0.0, 0.0, 1.0], (101, 1)), die_cool,
                               seed=seed + 40_000, t_s=np.arange(101) * 60.0)
    cal_cool = fit.model.compensate(cool.recording.raw_g, cool.recording.temperature_c(),
                                    extrapolate=True)
    before = thermal_drift(cool.recording.raw_g, die_cool)
    after = thermal_drift(cal_cool, die_cool)
    out["drift_before_ug_per_k"] = float(np.linalg.norm(before.slope_ug_per_k))
    out["drift_after_ug_per_k"] = float(np.linalg.norm(after.slope_ug_per_k))
    out["rmse_model_ug"] = float(np.sqrt(err_m.mean() / 3) * 1e6)
    out["rmse_oracle_ug"] = float(np.sqrt(err_o.mean() / 3) * 1e6)
    out["ratio"] = out["rmse_model_ug"] / out["rmse_oracle_ug"]
    return out


def run(sensors: int, method: str, **kw: object) -> dict[str, float]:
    rows = [heldout_case(s, method, **kw) for s in range(sensors)]  # type: ignore[arg-type]
    sse_m = sum(r["sse_model"] for r in rows)
    sse_o = sum(r["sse_oracle"] for r in rows)
    n = sum(r["n"] for r in rows)
    per_t = {T: float(np.sqrt(np.mean([r[f"ratio_{T:g}"] ** 2 for r in rows])))
             for T in HELDOUT_C}
    return {
        "method": method,
        "sensors": sensors,
        "rmse_model_ug": float(np.sqrt(sse_m / n / 3) * 1e6),
        "rmse_oracle_ug": float(np.sqrt(sse_o / n / 3) * 1e6),
        "ratio": float(np.sqrt(sse_m / sse_o)),
        "worst_sensor_ratio": max(r["ratio"] for r in rows),
        "drift_before_ug_per_k": float(np.median([r["drift_before_ug_per_k"] for r in rows])),
        "drift_after_ug_per_k": float(np.median([r["drift_after_ug_per_k"] for r in rows])),
        **{f"ratio_{T:g}C": v for T, v in per_t.items()},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sensors", type=int, default=10)
    ap.add_argument("--method", choices=("per_step", "joint", "both"), default=DEFAULT_METHOD)
    ap.add_argument("--orientations", type=int, default=60, help="per verification temperature")
    ap.add_argument("--temp-noise-c", type=float, default=0.1,
                    help="rms noise of one raw temperature sample, °C")
    ap.add_argument("--soak-min", type=float, default=60.0)
    ap.add_argument("--smooth-temperature-s", type=float, default=0.0,
                    help="smooth the verification run's temperature over this window (s)")
    ap.add_argument("--row-temp-noise-c", type=float, default=0.0,
                    help="extra white noise on every row's sensor_c, °C rms")
    ap.add_argument("--conditioning", choices=("raw", "default", "causal", "truth"),
                    default="raw",
                    help="verification temperature: each row's own reading (raw), as "
                    "`soakcal compensate` does by default, the causal filter alone, or the "
                    "noise-free channel (truth: isolates the calibration's share)")
    a = ap.parse_args(argv)
    methods = ("per_step", "joint") if a.method == "both" else (a.method,)
    ok = True
    print(f"held-out vector error, {a.sensors} simulated ADXL355, verification at "
          f"{', '.join(f'{t:g}' for t in HELDOUT_C)} °C x {a.orientations} random orientations")
    print(f"{'method':>9} {'model µg':>9} {'oracle µg':>9} {'ratio':>6} {'worst':>6}  "
          + " ".join(f"{f'{t:g}°C':>6}" for t in HELDOUT_C)
          + "  drift µg/K before→after   time")
    for m in methods:
        t0 = time.perf_counter()
        r = run(a.sensors, m, orientations=a.orientations, temp_noise_c=a.temp_noise_c,
                soak_min=a.soak_min, smooth_temperature_s=a.smooth_temperature_s,
                row_temp_noise_c=a.row_temp_noise_c, conditioning=a.conditioning)
        dt = time.perf_counter() - t0
        print(f"{m:>9} {r['rmse_model_ug']:9.2f} {r['rmse_oracle_ug']:9.2f} {r['ratio']:6.3f} "
              f"{r['worst_sensor_ratio']:6.3f}  "
              + " ".join(f"{r[f'ratio_{t:g}C']:6.3f}" for t in HELDOUT_C)
              + f"  {r['drift_before_ug_per_k']:8.1f} → {r['drift_after_ug_per_k']:6.2f}"
              + f"       {dt:5.1f} s")
        ok &= r["ratio"] <= REQUIRED_RATIO
    print(f"requirement ratio <= {REQUIRED_RATIO} (target {TARGET_RATIO}): "
          f"{'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
