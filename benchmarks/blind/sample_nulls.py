"""``diagnose`` on raw-sample recordings: false alarms on nulls, power on an effect (issue 10).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.blind.sample_nulls
        [--n 100] [--samples 20] [--effect scale_nonlinearity --size 40]
        [--vibration-mg 0.5] [--placement-ug 20] [--n-null 400] [--out F.json]

Each case: its own simulated sensor and seed, 11 steps −40…60 °C, Table 1, 20 min soaks,
the reference recorded, written in the *samples* shape of ``benchmarks.blind.memory``
(each position's capture as ``--samples`` rows, ``n`` = 1, no ``sd_*``: the capture's
mean error is shared by its samples). ``--effect``/``--size`` adds a catalogue effect
(``benchmarks.blind.catalogue.make``, size in its unit) to every case;
``--vibration-mg``/``--placement-ug`` as :func:`raw_sample_recording`. A false alarm (or,
with an effect, a detection) is ``mismatch`` true; Clopper–Pearson 95 % interval.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy import diagnose
from calibration.discrepancy.level import N_NULL
from calibration.recording import Recording
from simulators.truth import SensorTruth

SETPOINTS_C = [float(t) for t in range(-40, 61, 10)]


def raw_sample_recording(
    truth: SensorTruth,
    samples: int,
    seed: int,
    soak_min: float = 20.0,
    vibration_mg: float = 0.0,
    placement_ug: float = 0.0,
    **order: object,
) -> Recording:
    """Table 1 per step, each capture written back as ``samples`` raw rows.

    As ``benchmarks.blind.memory`` (*samples* shape): the simulator's capture mean plus
    the recorded per-sample scatter, so the mean's own error is common to the samples.
    ``vibration_mg``: compressor vibration (rms) on the steps below 0 °C, which widens
    those steps' sample scatter; ``placement_ug``: an error per capture and axis (rms,
    the same at every step) shared by its samples, as a box re-seated on the table.
    ``order``: ``simulate_campaign``'s ``position_order`` / ``position_order_seed``.
    """
    from calibration.schedules import table1
    from simulators.campaign_sim import RigPhysics, compressor_vibration, simulate_campaign

    physics = RigPhysics(vib_sd_g_by_step=compressor_vibration(SETPOINTS_C, 1e-3 * vibration_mg))
    rec = simulate_campaign(
        truth,
        SETPOINTS_C,
        table1(),
        soak_min=soak_min,
        samples_per_position=samples,
        seed=seed,
        physics=physics,
        **order,  # type: ignore[arg-type]
    )
    rng = np.random.default_rng(seed + 1)
    placed = 1e-6 * placement_ug * rng.standard_normal((len(rec), 3))
    return as_raw_samples(rec, samples, truth.odr_hz, rng, placed)



def as_raw_samples(
    rec: Recording, k: int, odr_hz: float, rng: np.random.Generator,
    placed_g: np.ndarray | None = None,
) -> Recording:
    """Each averaged row back to the ``k`` samples it was the mean of.

    Times spread across the capture window at ``odr_hz``; each sample is the row's
    mean plus ``placed_g`` (N,3, an error its samples share; none if None) plus the
    recorded per-sample scatter drawn from ``rng``.
    """
    c = rec.columns
    offsets = (np.arange(k) - (k - 1) / 2) / odr_hz
    keep = ("step", "setpoint_c", "chamber_c", "sensor_c", "position", "ref_x", "ref_y",
            "ref_z")
    cols = {name: np.repeat(c[name], k) for name in keep}
    cols["t_s"] = (c["t_s"][:, None] + offsets[None, :]).ravel()
    shared = np.zeros((len(rec), 3)) if placed_g is None else placed_g
    for i, (axis, sd) in enumerate((("ax", "sd_x"), ("ay", "sd_y"), ("az", "sd_z"))):
        cols[axis] = (
            c[axis][:, None] + shared[:, i, None]
            + c[sd][:, None] * rng.standard_normal((len(rec), k))
        ).ravel()
    cols["n"] = np.ones(len(rec) * k)
    return Recording.from_columns(cols)

def case(
    k: int,
    samples: int,
    n_null: int,
    effect: str | None,
    size: float,
    vibration_mg: float = 0.0,
    placement_ug: float = 0.0,
) -> dict:
    truth = SensorTruth.adxl355_typical(seed=7000 + k)
    if effect:
        from benchmarks.blind.catalogue import draw_pattern, make
        from benchmarks.blind.protocols import PROTOCOLS

        pat = draw_pattern(np.random.default_rng(k), PROTOCOLS["short_soak"], 0)
        truth.effects = [make(effect, size, pat, PROTOCOLS["short_soak"]).effect]
    rec = raw_sample_recording(truth, samples, 17000 + k, 20.0, vibration_mg, placement_ug)
    d = diagnose(rec, n_null=n_null, seed=k)
    return {
        "case": k,
        "mismatch": d.mismatch,
        "noise_source": d.noise_source,
        "findings": [f.effect for f in d.findings],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--samples", type=int, default=20, help="rows per position capture")
    # diagnose's own replicates: at the verdict's level (level.ALPHA) 200 cannot resolve α/2
    ap.add_argument("--n-null", type=int, default=N_NULL)
    ap.add_argument("--effect", default=None)
    ap.add_argument("--size", type=float, default=0.0)
    ap.add_argument("--vibration-mg", type=float, default=0.0, help="below 0 °C, rms")
    ap.add_argument("--placement-ug", type=float, default=0.0, help="per capture, rms")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = [
        case(k, a.samples, a.n_null, a.effect, a.size, a.vibration_mg, a.placement_ug)
        for k in range(a.n)
    ]
    hits = sum(bool(r["mismatch"]) for r in rows)
    lo, hi = clopper_pearson(hits, len(rows))
    named: dict[str, int] = {}
    for r in rows:
        for f in r["findings"]:
            named[f] = named.get(f, 0) + 1
    res = {
        "vibration_mg": a.vibration_mg,
        "placement_ug": a.placement_ug,
        "effect": a.effect,
        "size": a.size,
        "samples": a.samples,
        "mismatch": hits,
        "n": len(rows),
        "rate": hits / len(rows),
        "ci95": [lo, hi],
        "named": named,
        "wall_s": round(time.perf_counter() - t0, 1),
    }
    if a.out:
        with open(a.out, "w") as fh:
            json.dump({**res, "cases": rows}, fh, indent=1)
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
