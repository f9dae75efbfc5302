"""Blind-benchmark generator: twin recordings with ONE concealed effect (or none).

    python -m benchmarks.blind.generate --out benchmarks/blind/out [--quick] [--reps 3]

Writes ``OUT/cases/NNNN.csv`` (recording v1, the same columns for every case
of a protocol) and, apart, ``OUT/keys/NNNN.json`` (effect id, parameters,
protocol, magnitude, minimum detectable size, λ). Case kinds:

* ``effect``  -- an effect visible under the protocol, at 0.5×…8× its minimum
  detectable size (computed for that sensor, pattern and protocol; for effects on
  a few unknown readings including the search over all readings, detectability.py);
* ``hidden``  -- an effect at a physically typical size that the protocol hides
  (λ < 1): a diagnoser must not name it (ideally lists it as not identifiable);
* ``decoy``   -- no effect, but base-model terms at the edge of the datasheet
  (strong cubic curvature, large misalignment, max offset tempco);
* ``null``    -- no effect, different sensors, seeds and protocols.

Confuser pairs are built in: lag, hysteresis and drift share ``updown_short``;
nonlinearity on Table 1 competes with bias/scale.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass
from multiprocessing import Pool
from pathlib import Path

import numpy as np

from benchmarks.blind import twin
from benchmarks.blind.catalogue import ROWWISE, UNIT, draw_pattern, make
from benchmarks.blind.protocols import PROTOCOLS
from calibration.recording import write_recording
from simulators.truth import SensorTruth

MULTIPLES = (0.5, 1.0, 2.0, 4.0, 8.0)
VISIBLE: tuple[tuple[str, str], ...] = (
    ("thermal_lag", "short_soak"), ("thermal_lag", "updown_short"),
    ("thermal_hysteresis", "updown"), ("thermal_hysteresis", "updown_short"),
    ("scale_nonlinearity", "oblique"), ("scale_nonlinearity", "oneway"),
    ("cross_coupling", "oblique"),
    ("bias_drift", "updown"), ("bias_drift", "updown_short"),
    ("session_offset", "updown"),
    ("outlier", "oneway"), ("outlier", "oblique"),
    ("vibration_rectification", "oneway"),
    ("temperature_sensor", "oneway"),
    ("turntable_geometry", "oblique"),
    ("self_heating", "updown_short"),
)
HIDDEN: tuple[tuple[str, str, float], ...] = (  # effect, protocol, typical magnitude (UNIT)
    ("thermal_lag", "oneway", 900.0),
    ("self_heating", "oneway", 2.0),
    ("local_gravity", "oblique", 500.0),
    ("lever_arm", "oneway", 50.0),
    ("filter_delay", "oneway", 5.0),
    ("temperature_rate", "short_soak", 100.0),
    ("bias_drift", "oneway", 5.0),
)
DECOYS = ("strong_curvature", "large_misalignment", "max_tempco")
QUICK_VISIBLE = (("thermal_lag", "short_soak"), ("thermal_hysteresis", "updown"),
                 ("scale_nonlinearity", "oblique"), ("bias_drift", "updown"),
                 ("outlier", "oneway"))


@dataclass
class CaseSpec:
    case: str
    kind: str  # effect | hidden | decoy | null
    protocol: str
    seed: int
    effect: str | None = None
    multiple: float | None = None
    magnitude: float | None = None
    decoy: str | None = None


def plan(quick: bool, reps: int, n_null: int, seed0: int = 1) -> list[CaseSpec]:
    specs: list[CaseSpec] = []

    def add(**kw: object) -> None:
        specs.append(CaseSpec(case=f"{len(specs):04d}", seed=seed0 * 100_000 + len(specs),
                              **kw))  # type: ignore[arg-type]

    visible = QUICK_VISIBLE if quick else VISIBLE
    multiples = (1.0, 4.0) if quick else MULTIPLES
    for eid, proto in visible:
        for m in multiples:
            for _ in range(reps):
                add(kind="effect", protocol=proto, effect=eid, multiple=m)
    for eid, proto, mag in HIDDEN[:3] if quick else HIDDEN:
        for _ in range(1 if quick else reps):
            add(kind="hidden", protocol=proto, effect=eid, magnitude=mag)
    protos = list(PROTOCOLS)
    for i, d in enumerate(DECOYS):
        for r in range(1 if quick else 2 * reps):
            add(kind="decoy", protocol=protos[(i + r) % len(protos)], decoy=d)
    for i in range(n_null):
        add(kind="null", protocol=protos[i % len(protos)])
    # Case ids in random order: the id must not betray the kind (seeds stay in the keys).
    perm = np.random.default_rng(seed0).permutation(len(specs))
    for spec, k in zip(specs, perm, strict=True):
        spec.case = f"{k:04d}"
    return specs


def sensor(seed: int, decoy: str | None) -> SensorTruth:
    truth = SensorTruth.adxl355_typical(seed)
    rng = np.random.default_rng(seed + 7)
    c = truth.coeffs
    if decoy == "strong_curvature":
        c[0:3, 2] = rng.choice([-1, 1], 3) * 3e-6  # g/°C²: ~4 mg at ±35 °C
        c[0:3, 3] = rng.choice([-1, 1], 3) * 5e-8  # g/°C³: ~2 mg at ±35 °C
    elif decoy == "large_misalignment":
        c[9:12, 0] = rng.choice([-1, 1], 3) * 0.03  # rad
        c[6:9, 0] = rng.choice([-1, 1], 3) * 0.01
    elif decoy == "max_tempco":
        c[0:3, 1] = rng.choice([-1, 1], 3) * 0.15e-3  # g/°C, datasheet max
    elif decoy is not None:
        raise ValueError(decoy)
    return truth


def build(spec: CaseSpec, out: Path) -> dict:
    """Simulate one case; write its recording and its key; return the key."""
    proto = PROTOCOLS[spec.protocol]
    truth = sensor(spec.seed, spec.decoy)
    rng = np.random.default_rng(spec.seed)
    concealed, key_extra = None, {}
    if spec.effect is not None:
        pat = draw_pattern(rng, proto, 0)
        mds = twin.minimum_detectable(spec.effect, pat, proto, truth)
        mag = spec.magnitude if spec.magnitude is not None else spec.multiple * mds
        concealed = make(spec.effect, mag, pat, proto)
        lam = twin.lambda_fn(spec.effect, pat, proto, truth)(mag)
        key_extra = {"magnitude": mag, "unit": UNIT[spec.effect], "mds": mds, "lambda": lam,
                     "parameters": _jsonable(concealed.parameters),
                     "expected_detectable": bool(np.isfinite(mds) and mag >= mds)}
        if spec.effect in ROWWISE:  # λ of each disturbed reading (the MDS criterion)
            lr = twin.row_lambdas(spec.effect, pat, proto, truth, mag)
            key_extra["lambda_rows"] = [float(lr[r]) for r in pat["rows"]]
            # The pre-2026-11 criterion (one test of all readings, no search), for reference.
            key_extra["mds_without_search"] = twin.minimum_detectable_single_test(
                spec.effect, pat, proto, truth)
    rec = twin.recording(proto, truth, concealed, spec.seed)
    write_recording(out / "cases" / f"{spec.case}.csv", rec)
    key = {**asdict(spec), **key_extra, "sensor_seed": spec.seed,
           "protocol_description": proto.description}
    (out / "keys").mkdir(parents=True, exist_ok=True)
    (out / "keys" / f"{spec.case}.json").write_text(json.dumps(key, indent=1))
    return key


def _jsonable(v: object) -> object:
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, list | tuple | np.ndarray):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _build_star(args: tuple[CaseSpec, Path]) -> dict:
    return build(*args)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("benchmarks/blind/out"))
    ap.add_argument("--quick", action="store_true", help="small subset (< 2 min end to end)")
    ap.add_argument("--reps", type=int, default=None, help="repeats per cell (full: 3)")
    ap.add_argument("--nulls", type=int, default=None, help="null cases (full: 200)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    reps = a.reps if a.reps is not None else (1 if a.quick else 3)
    n_null = a.nulls if a.nulls is not None else (20 if a.quick else 200)
    specs = plan(a.quick, reps, n_null, a.seed)
    for sub in ("cases", "keys"):
        d = a.out / sub
        d.mkdir(parents=True, exist_ok=True)
        for f in d.glob("*"):
            f.unlink()
    with Pool(a.jobs) as pool:
        keys = pool.map(_build_star, [(s, a.out) for s in specs], chunksize=4)
    kinds = {k: sum(1 for x in keys if x["kind"] == k) for k in ("effect", "hidden", "decoy",
                                                                   "null")}
    print(f"wrote {len(keys)} cases to {a.out}/cases (keys apart in {a.out}/keys): {kinds}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
