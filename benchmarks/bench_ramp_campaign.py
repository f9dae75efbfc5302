"""Ramp campaigns: campaign time (dry run and simulated run) and held-out accuracy.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ramp_campaign.py \
        [--sensors 16] [--rate 3] [--seed 0] [--hysteresis-ug 15] [--no-soak]

**Campaign time.** (1) The dry run ``soakcal campaign plan --method ramp`` computes for
the built-in ``sim`` rig (:func:`service.dry_run.check_campaign`: the ramp plan on a
first-order die of the prior lag, 15 min, the table's own travel per move). (2) A
simulated run (:func:`simulators.ramp_campaign_sim.simulate_ramp_campaign`): the same
plan on ``--sensors`` dies with lags spread over 300…900 s, the turnaround holds ending
on the measured approach of the slowest. Against the seed's 13.9 h for one sensor: the
aim is 16 sensors in ≤ 0.25 × 13.9 h = 3.475 h.

**Held-out error** (as ``bench_ramp_fit.py``): the twin's sensors
(``ramp_twin_sensors``: ADXL355 magnitudes, rate gain 20 µg per °C/min, hysteresis
``--hysteresis-ug``, die lags 300…900 s), channel noise 0.1 °C per row and a 0.11 °C
quantum; each recording calibrated as ``soakcal calibrate`` does (plateaus, the gate,
the continuous fit); a fresh static verification run at −35, −5, 25, 45 °C with 60 random
orientations each; ratio = pooled RMS vector error / the noise-limited oracle (true
parameters at the true die temperature on the same readings). Against a soak campaign of
the same sensors (11 setpoints, 60 min soaks, each sensor's die lag, the same channel),
fitted by ``fit_campaign``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "benchmarks"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from bench_ramp_fit import heldout_sse, noisy_channel  # noqa: E402

from calibration import gate  # noqa: E402
from calibration.continuous import fit_continuous  # noqa: E402
from calibration.plateaus import segment_recording  # noqa: E402
from calibration.thermal import fit_campaign  # noqa: E402
from simulators.campaign_sim import RigPhysics, simulate_campaign  # noqa: E402
from simulators.ramp_campaign_sim import RampCampaignSpec, simulate_ramp_campaign  # noqa: E402
from simulators.ramp_sim import ramp_twin_sensors  # noqa: E402

SEED_HOURS = 13.9
AIM_FRACTION = 0.25


def dry_run_hours(n_sensors: int, rate: float) -> tuple[float, str]:
    from service.campaigns import SIM_RIG
    from service.dry_run import check_campaign
    from service.engine.spec import EngineSpec

    spec = EngineSpec.model_validate({"method": "ramp", "ramp_c_per_min": rate,
                                        "setpoints_c": [-40, 60]})
    check = check_campaign(spec, dict(SIM_RIG), "sim")
    if not check.ok:
        raise SystemExit(f"dry run refused: {check.issues}")
    return float(check.predicted_duration_s or 0.0) / 3600.0, check.summary()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sensors", type=int, default=16)
    ap.add_argument("--rate", type=float, default=3.0, help="chamber ramp, °C/min")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--hysteresis-ug", type=float, default=15.0)
    ap.add_argument("--no-soak", action="store_true", help="skip the soak comparison")
    a = ap.parse_args()

    dry_h, summary = dry_run_hours(a.sensors, a.rate)
    print(f"dry run (sim rig): {summary}")
    truths, taus = ramp_twin_sensors(a.sensors, a.seed, hysteresis_ug=a.hysteresis_ug)
    w0 = time.monotonic()
    camp = simulate_ramp_campaign(truths, taus, RampCampaignSpec(ramp_c_per_min=a.rate),
                                  seed=a.seed + 100, temp_row_noise_c=0.1, temp_lsb_c=0.11)
    sim_h = camp.duration_s / 3600.0
    print(f"simulated run: {a.sensors} sensors, die lags {min(taus):.0f}…{max(taus):.0f} s, "
          f"{len(camp.recordings[0])} captures each, legs "
          + ", ".join(f"→{leg['target_c']:g} °C {(leg['end_s'] - leg['start_s']) / 60:.0f} min"
                      for leg in camp.legs)
          + f"; campaign {sim_h:.3f} h ({time.monotonic() - w0:.1f} s wall)")
    aim_h = AIM_FRACTION * SEED_HOURS
    print(f"campaign time: dry run {dry_h:.3f} h = {dry_h / SEED_HOURS:.3f}× the seed's "
          f"{SEED_HOURS} h, simulated {sim_h:.3f} h = {sim_h / SEED_HOURS:.3f}×; aim ≤ "
          f"{aim_h:.3f} h ({AIM_FRACTION}×): {'met' if max(dry_h, sim_h) <= aim_h else 'NOT met'}")

    sse = {"ramp": 0.0, "soak": 0.0, "oracle": 0.0}
    for i, (rec, truth, tau) in enumerate(zip(camp.recordings, truths, taus, strict=True)):
        w1 = time.monotonic()
        seg = segment_recording(rec)
        decided = gate.plan(rec, continuous=seg.is_continuous)
        if decided.kind != "continuous":
            print(f"  sensor {i}: the gate decided {decided.kind!r}, not continuous: "
                  f"{decided.reason}")
            return 1
        fit = fit_continuous(rec, seg)
        gate.check_model(fit.model, rec, fit.row_temperature_c)
        m_r, o = heldout_sse(fit.model, truth, a.seed + 400 + i)
        line = (f"  sensor {i}: tau {tau:.0f} s, die {camp.die_c[:, i].min():.1f}…"
                f"{camp.die_c[:, i].max():.1f} °C, {len(seg.plateau_ids)} plateau(s), "
                f"{seg.continuous_rows} continuous rows, degree {fit.model.degree}, ramp / "
                f"oracle {np.sqrt(m_r / o):.3f}")
        sse["ramp"] += m_r
        sse["oracle"] += o
        if not a.no_soak:
            soak = simulate_campaign(truth, seed=a.seed + 200 + i,
                                     physics=RigPhysics(die_tau_s=tau))
            soak = noisy_channel(soak, 0.1, 0.11, a.seed + 300 + i)
            m_s, o2 = heldout_sse(fit_campaign(soak).model, truth, a.seed + 400 + i)
            assert o == o2  # one verification run judges both
            sse["soak"] += m_s
            line += f", soak / oracle {np.sqrt(m_s / o):.3f}"
        print(line + f" ({time.monotonic() - w1:.1f} s)", flush=True)
    ramp = float(np.sqrt(sse["ramp"] / sse["oracle"]))
    out = f"pooled: ramp / oracle {ramp:.3f}"
    if not a.no_soak:
        soak_r = float(np.sqrt(sse["soak"] / sse["oracle"]))
        out += f", soak / oracle {soak_r:.3f}, ramp / soak {ramp / soak_r:.3f}"
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
