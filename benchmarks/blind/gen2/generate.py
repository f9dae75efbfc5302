"""Second, independently written generator of the blind benchmark.

    python -m benchmarks.blind.gen2.generate --realdata DIR --out OUT [--quick] [--reps R]
                                             [--nulls N] [--seed S]
                                             [--outside-set default|unseen]
                                             [--temperature-channel dithered|clean|clean-declared]
                                             [--poses]

Writes ``OUT/cases/NNNN.csv`` (and ``OUT/given/NNNN.csv`` for twin-against-recording
pairs: the recording a model is calibrated on) and, apart, ``OUT/keys/NNNN.json``. Nothing
here imports the project's twin (``simulators/``) or the diagnosis' effect physics: the
sensor (sensor.py), the protocols (protocol.py), the effects (effects.py) and the noise
(realnoise.py, drawn from the shared real recordings) are written afresh. Case kinds:

* ``null`` — no effect; random protocols (one-way up or down staircases, up-down,
  irregular order of temperatures, sparse 5-temperature campaigns, 10–45 min soaks, 24, 18
  or 36 positions, shuffled/skipped positions, 20–200 samples per capture, vibration that is
  not rectified), each its own sensor;
* ``catalogue`` — one catalogue effect at 1× and 2× its minimum detectable size (detect.py)
  under a protocol that shows it; a case where it stays undetectable is ``hidden``;
* ``outside`` — an ADC error confined to a band of codes; a crack that appears in the middle
  of a plateau (a bias and scale change of one axis from then on). With ``--outside-set
  unseen``, five others instead (unseen_effects.py: fixture creep after each turn, a bias
  jump at a die temperature, a periodic chamber disturbance, frost below the dew point, a
  cable pulling by table angle), each at twice its minimum detectable size;
* ``against`` — a model calibrated on one recording held against another of the same
  sensor: unchanged on another protocol (a one-way staircase, sparse positions), or
  re-mounted 2 mrad about its z axis.

``--temperature-channel clean``: the sensor_c channel's own per-sample noise is 0.003 °C
(simulate.CLEAN_CH_SD_C) instead of 0.04 °C, at the protocol's LSB: it does not dither, so
the readings of a settled plateau share one rounding error, uniform in ±LSB/2. Same draws
otherwise (the default cases with only that channel's noise changed).
``--temperature-channel clean-declared``: the same cases, each recording declaring its
sensor_c LSB in the optional ``sensor_lsb_c`` column (calibration/temperature_lsb.py).
``--poses``: every recording also gives the table's commanded pose of each reading
(``pose_qw`` … ``pose_qz``), as soakcal's engine writes it; the same draws otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, replace
from multiprocessing import Pool
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.blind.gen2 import detect
from benchmarks.blind.gen2 import effects as fx
from benchmarks.blind.gen2 import protocol as pr
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2 import unseen_effects as ux
from benchmarks.blind.gen2.protocol import KINDS, draw_protocol
from benchmarks.blind.gen2.realnoise import RealDataMissing, load_pools, realdata_dir
from benchmarks.blind.gen2.sensor import draw_sensor
from benchmarks.blind.gen2.unseen import UNSEEN_KINDS, lagging_die
from calibration.recording import write_recording

REMOUNT_RAD = 2e-3
OUTSIDE_SIZE_UG = {"adc_band": 80.0, "crack": 60.0}
MAX_LAG_S = 7200.0  # a die lag beyond 2 h is not a fixture; longer m* means "hidden"
_POOLS: dict = {}


def _need(eid: str) -> dict:
    """Protocol constraints under which an effect can show."""
    return {"thermal_lag": {"columns": ("chamber_c",)},
            "thermal_hysteresis": {"kind": "updown"}, "bias_drift": {"kind": "updown"},
            "session_offset": {"kind": "updown"},
            "temperature_rate": {"columns": ("sensor_c",), "soak_min": 10.0},
            "temperature_sensor": {"columns": ("sensor_c",)},
            "cross_coupling": {"schedule": "oblique36"}}.get(eid, {})


def plan(quick: bool, reps: int, n_null: int, seed0: int,
         protocols: str = "default", outside_set: str = "default",
         temperature_channel: str = "dithered", poses: bool = False) -> list[dict]:
    """The cases. ``protocols="unseen"`` draws every protocol from the unseen family
    (unseen.py; nulls cycle through its variants); ``outside_set="unseen"`` plans the
    outside effects of unseen_effects.py instead of ``adc_band`` and ``crack``. The default
    plan is unchanged."""
    specs: list[dict] = []
    extra = {} if protocols == "default" else {"family": protocols}
    if temperature_channel != "dithered":
        extra["temperature_channel"] = temperature_channel
    if poses:
        extra["poses"] = True
    kinds = KINDS if protocols == "default" else UNSEEN_KINDS

    def add(**kw) -> None:
        specs.append({"seed": seed0 * 100_000 + len(specs), **kw, **extra})

    for i in range(n_null):
        add(kind="null", proto_kind=kinds[i % len(kinds)])
    for eid in fx.DOF:
        for mult in (1.0, 2.0):
            for _ in range(reps):
                add(kind="catalogue", effect=eid, multiple=mult)
    for eid in fx.OUTSIDE if outside_set == "default" else ux.UNSEEN_OUTSIDE:
        for _ in range(2 * reps):
            add(kind="outside", effect=eid)
    for change in ("unchanged", "remount_z"):
        for _ in range(2 * reps if quick else 3 * reps):
            add(kind="against", change=change)
    perm = np.random.default_rng(seed0).permutation(len(specs))
    for s, k in zip(specs, perm, strict=True):
        s["case"] = f"{k:04d}"
    return specs


def build(spec: dict, out: Path) -> dict:
    pools = _POOLS["pools"]
    rng = np.random.default_rng(spec["seed"])
    sensor = draw_sensor(rng)
    key = dict(spec)
    eid, m = spec.get("effect"), 0.0
    if spec["kind"] == "against":
        return _build_against(spec, sensor, rng, out)
    for _attempt in range(6):
        need = {"kind": spec.get("proto_kind"), **(_need(eid) if eid else {})}
        proto = _channel(draw_protocol(rng, **need, family=spec.get("family", "default")),
                         spec)
        pat = fx.pattern(rng, len(proto.setpoints_c), 10_000)
        if eid in ux.UNSEEN_OUTSIDE:  # its own draws: the default cases' stay as they were
            pat.update(ux.unseen_pattern(spec["seed"], proto.setpoints_c))
        n_read = len(sim.scene(proto, None, 0.0, pat, spec["seed"]).t_s)
        pat["rows"] = sorted(rng.choice(n_read, 2, replace=False).tolist())
        if spec["kind"] != "catalogue":
            break
        mds = detect.minimum_detectable(proto, sensor, pools, eid, pat, spec["seed"])
        if eid == "thermal_lag" and mds > MAX_LAG_S:
            mds = float("inf")
        if np.isfinite(mds):
            break
    if spec["kind"] == "catalogue":
        key.update(mds=mds, unit=fx.UNIT[eid], catalogue_id=fx.CATALOGUE_ID[eid])
        if np.isfinite(mds):
            m = spec["multiple"] * mds
        else:
            key["kind"] = "hidden"
            m = {"thermal_lag": 1800.0}.get(eid, 50.0)
        key["magnitude"] = m
    elif spec["kind"] == "outside" and eid in ux.UNSEEN_OUTSIDE:
        # twice the minimum detectable size under this protocol (detect.py's λ), so no case
        # is invisible; a size the protocol cannot show at all falls back to 50 µg
        mds = detect.minimum_detectable(proto, sensor, pools, eid, pat, spec["seed"])
        m = ux.SIZE_MULTIPLE * mds if np.isfinite(mds) else 50.0
        key.update(magnitude=m, unit=ux.UNIT[eid], mds=mds, multiple=ux.SIZE_MULTIPLE)
    elif spec["kind"] == "outside":
        m = OUTSIDE_SIZE_UG[eid]
        key.update(magnitude=m, unit=fx.UNIT[eid])
    elif spec["kind"] == "null" and lagging_die(proto):
        key.update(_slow_die_key(proto, sensor, pools, pat, spec["seed"]))
    cols = _declared(sim.record(proto, sensor, pools, eid, m, pat, spec["seed"]), proto, spec)
    write_recording(out / "cases" / f"{spec['case']}.csv", cols)
    key.update(protocol=proto.name, protocol_detail=asdict(proto), pattern=pat)
    (out / "keys" / f"{spec['case']}.json").write_text(
        json.dumps(key, indent=1, default=_json_default))
    return key


def _channel(proto, spec: dict):
    """The protocol with the spec's temperature channel (clean: no dither; see the module
    docstring); the default spec's protocol unchanged."""
    if spec.get("temperature_channel") in ("clean", "clean-declared"):
        return replace(proto, sensor_c_sd_c=sim.CLEAN_CH_SD_C)
    return proto


def _declared(cols: dict, proto, spec: dict) -> dict:
    """The recording's columns with what the spec has it declare: its sensor_c LSB
    (``sensor_lsb_c``) when the channel is ``clean-declared``; the table's commanded pose
    of each reading (``pose_qw`` … ``pose_qz``, the rotation from sensor to lab as a unit
    quaternion, scalar first) when the spec asks for ``poses``; else as they are."""
    if spec.get("temperature_channel") == "clean-declared" and "sensor_c" in cols:
        cols = {**cols, "sensor_lsb_c": np.full(len(cols["t_s"]), proto.sensor_c_lsb_c)}
    if spec.get("poses"):
        cols = {**cols, **_pose_columns(proto, cols["position"])}
    return cols


def _pose_columns(proto, position: np.ndarray) -> dict:
    """The commanded pose of each reading: force = Rz(α)ᵀ·Rx(β)ᵀ·up (protocol.py), so the
    rotation from sensor to lab is R = Rx(β)·Rz(α); commanded, so an encoder's error is
    not in it."""
    ang = np.deg2rad(proto.angles_deg())[np.asarray(position, int)]
    R = np.array([pr.rot_x(b) @ pr.rot_z(a) for a, b in ang])
    xyzw = Rotation.from_matrix(R).as_quat()
    q = xyzw[:, [3, 0, 1, 2]] * np.where(xyzw[:, 3:] < 0, -1.0, 1.0)
    return {f"pose_q{c}": q[:, i] for i, c in enumerate("wxyz")}


def _slow_die_key(proto, sensor, pools, pat: dict, seed: int) -> dict:
    """A chamber_c-only null on a slow die is a ``thermal_lag`` case (τ = the die's): its
    size against the lag's minimum detectable one under this protocol (detect.py, with the
    die otherwise settled, τ = 20 s), so the scorer does not count it as a null."""
    settled = replace(proto, die_tau_s=20.0)
    mds = detect.minimum_detectable(settled, sensor, pools, "thermal_lag", pat, seed)
    return {"kind": "slow_die", "effect": "thermal_lag", "catalogue_id": "thermal_lag",
            "magnitude": proto.die_tau_s, "unit": "s", "mds": mds,
            "multiple": proto.die_tau_s / mds if np.isfinite(mds) else 0.0}


def _build_against(spec: dict, sensor, rng: np.random.Generator, out: Path) -> dict:
    pools = _POOLS["pools"]
    cal = _channel(draw_protocol(rng, kind="updown", schedule="dense24",
                                 columns=("sensor_c",), soak_min=20.0), spec)
    again = _channel(draw_protocol(rng, kind=str(rng.choice(["oneway", "staircase_down",
                                                              "sparse"])),
                                   columns=("sensor_c",)), spec)
    pat = fx.pattern(rng, 3, 10)
    write_recording(out / "given" / f"{spec['case']}.csv",
                    _declared(sim.record(cal, sensor, pools, None, 0.0, pat, spec["seed"]),
                              cal, spec))
    moved = sensor.rotated_z(REMOUNT_RAD) if spec["change"] == "remount_z" else sensor
    write_recording(out / "cases" / f"{spec['case']}.csv",
                    _declared(sim.record(again, moved, pools, None, 0.0, pat, spec["seed"] + 7),
                              again, spec))
    key = {**spec, "protocol": again.name, "given_protocol": cal.name,
           "remount_rad": REMOUNT_RAD if spec["change"] == "remount_z" else 0.0}
    (out / "keys" / f"{spec['case']}.json").write_text(
        json.dumps(key, indent=1, default=_json_default))
    return key


def _json_default(v: object) -> object:
    """numpy values for json.dumps (non-finite floats stay Infinity/NaN, read back by json)."""
    return v.tolist() if isinstance(v, np.ndarray | np.generic) else str(v)


def _init(realdata: str) -> None:
    _POOLS["pools"] = load_pools(Path(realdata))


def _build_star(args: tuple[dict, Path]) -> dict:
    return build(*args)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None,
                    help="directory of the shared real recordings (or SOAKCAL_REALDATA)")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/blind/gen2/out"))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--nulls", type=int, default=None, help="null cases (quick 15, full 300)")
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--protocols", choices=("default", "unseen"), default="default",
                    help="protocol family: the default draws, or variants they never draw "
                         "(unseen.py; null, catalogue and outside cases)")
    ap.add_argument("--only", default=None,
                    help="comma list of effects, kinds (null, outside, against) or changes "
                         "to keep; the others are planned (so seeds stay) but not written")
    ap.add_argument("--outside-set", choices=("default", "unseen"), default="default",
                    help="outside-catalogue effects: adc_band and crack, or the five of "
                         "unseen_effects.py the diagnosis was never developed on")
    ap.add_argument("--temperature-channel", choices=("dithered", "clean", "clean-declared"),
                    default="dithered",
                    help="the sensor_c channel's per-sample noise: 0.04 °C (dithers its LSB) or "
                         "0.003 °C (clean: a settled plateau's readings share one rounding "
                         "error; clean-declared: the same, its LSB in a sensor_lsb_c column)")
    ap.add_argument("--poses", action="store_true",
                    help="each recording also gives the table's commanded pose per reading "
                         "(pose_qw … pose_qz), as soakcal's engine writes it")
    a = ap.parse_args(argv)
    try:
        rd = realdata_dir(a.realdata)
    except RealDataMissing as exc:
        print(exc, file=sys.stderr)
        return 2
    n_null = a.nulls if a.nulls is not None else (15 if a.quick else 300)
    specs = plan(a.quick, a.reps, n_null, a.seed, a.protocols, a.outside_set,
                 a.temperature_channel, a.poses)
    if a.only:
        keep = set(a.only.split(","))
        specs = [s for s in specs if keep & {s["kind"], s.get("effect"), s.get("change")}]
    for sub in ("cases", "keys", "given"):
        d = a.out / sub
        d.mkdir(parents=True, exist_ok=True)
        for f in d.glob("*"):
            f.unlink()
    with Pool(a.jobs, initializer=_init, initargs=(str(rd),)) as pool:
        keys = pool.map(_build_star, [(s, a.out) for s in specs], chunksize=2)
    kinds = {k: sum(x["kind"] == k for x in keys) for k in
             ("null", "catalogue", "hidden", "outside", "against", "slow_die")}
    print(f"wrote {len(keys)} cases to {a.out}/cases (keys apart in {a.out}/keys): {kinds}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
