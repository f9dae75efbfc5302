"""One case's protocol, sensor and effect drawn again with fresh noise: how ``by_fit`` names.

Usage::

    python -m benchmarks.blind.gen2.name_margin --realdata DIR --key OUT/keys/0167.json \
        --draws 40 [--white] [--pair thermal_hysteresis,bias_drift]

Why (issue 22): a ``thermal_hysteresis`` case at twice its detectable size was named
``temperature_rate`` by :func:`calibration.discrepancy.by_fit.name_by_fit`. One case cannot
say whether that protocol separates the two; the same protocol, sensor and effect drawn
with ``--draws`` noise seeds can. For each draw it prints the top finding and each
confuser's explained sum of squares in noise variances (``q / s²``, the quantity the
margin compares), then the spread of ``q_rate − q_hysteresis`` (``--pair TRUE,RIVAL``: of
``q_RIVAL − q_TRUE``). Under the margin's model
(white Gaussian noise, the truth in one span) that difference is N(−λ², 2λ), so its sd
should be 2·√(−mean); a larger sd is evidence the margin's error bound (≤ 2.5 % per pair)
does not hold on this noise. ``--white``: independent Gaussian samples instead of the real
noise pools (same scales), to tell the noise's structure from the design's.
"""

from __future__ import annotations

import argparse
import importlib
import json
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.blind.gen2 import protocol as pr
from benchmarks.blind.gen2 import simulate as sim
from benchmarks.blind.gen2.realnoise import load_pools, realdata_dir
from benchmarks.blind.gen2.sensor import draw_sensor
from calibration.discrepancy import by_fit
from calibration.discrepancy.effects import BY_ID
from calibration.recording import read_recording, write_recording

PAIR = ("thermal_hysteresis", "temperature_rate", "session_offset", "bias_drift")
MARGIN_SD_PER_ROOT = 2.0  # sd of Δq = 2λ under the margin's model (by_fit.MARGIN)


def _logging_name_by_fit(log: list[dict]):
    """``name_by_fit`` that also records each rival's q/s² at its first call."""
    orig = by_fit.name_by_fit

    def wrapped(best, tests, e, n_cols, explained, alpha, ctx=None):
        out = orig(best, tests, e, n_cols, explained, alpha, ctx)
        s2 = float(e @ e) / max(e.size - n_cols, 1)
        q = {}
        for g in PAIR:
            if g in tests:
                got, _ = by_fit._profile(BY_ID[g], tests[g], explained)
                q[g] = max(got.values()) / s2
        log.append(q)
        return out
    return wrapped


def _protocol(detail: dict) -> pr.Protocol2:
    return pr.Protocol2(**{k: tuple(v) if isinstance(v, list) else v for k, v in detail.items()})


def _white(pools) -> None:
    """Independent unit Gaussian samples in place of the real pools' blocks."""
    cls = type(pools)
    cls.block = lambda self, rng, pool, n: rng.standard_normal((n, 3))
    cls.mean_variance = lambda self, pool, n, draws=400, seed=0: 1.0 / n


def top_of(d: dict) -> str:
    fs = d.get("findings") or []
    if not fs:
        return "none"
    f = fs[0]
    if f["effect"] == "not_identifiable":
        return "not separable: " + "+".join(sorted(f["where"].get("candidates", [])))
    return f["effect"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=None)
    ap.add_argument("--key", type=Path, required=True, help="a generated case's key (json)")
    ap.add_argument("--draws", type=int, default=40)
    ap.add_argument("--multiple", type=float, default=None,
                    help="size in detectable sizes (default: the key's magnitude)")
    ap.add_argument("--white", action="store_true")
    ap.add_argument("--protocol", default="{}",
                    help='protocol fields to change, JSON (e.g. \'{"sensor_c_sd_c": 0.0005, '
                         '"sensor_c_lsb_c": 0.0001}\': a near-exact temperature channel)')
    ap.add_argument("--pair", default=f"{PAIR[0]},{PAIR[1]}",
                    help="TRUE,RIVAL: the spread of q_RIVAL − q_TRUE is reported")
    a = ap.parse_args(argv)
    true_id, rival_id = a.pair.split(",")
    diagnose_mod = importlib.import_module("calibration.discrepancy.diagnose")
    log: list[dict] = []
    by_fit.name_by_fit = _logging_name_by_fit(log)
    key = json.loads(a.key.read_text())
    proto = _protocol({**key["protocol_detail"], **json.loads(a.protocol)})
    sensor = draw_sensor(np.random.default_rng(key["seed"]))
    pools = load_pools(realdata_dir(a.realdata))
    if a.white:
        _white(pools)
    m = key["magnitude"] if a.multiple is None else key["mds"] * a.multiple
    tally: dict[str, int] = {}
    diff = []
    path = Path(tempfile.mkdtemp()) / "case.csv"
    for i in range(a.draws):
        write_recording(path, sim.record(proto, sensor, pools, key["effect"], m, key["pattern"],
                                         key["seed"] + 1000 * (i + 1)))
        log.clear()
        d = json.loads(diagnose_mod.diagnose(read_recording(path), seed=i, n_null=400).to_json())
        top = top_of(d)
        tally[top] = tally.get(top, 0) + 1
        q = log[0] if log else {}
        if true_id in q and rival_id in q:
            diff.append(q[rival_id] - q[true_id])
        print(i, top, " ".join(f"{g}={v:.1f}" for g, v in q.items()), flush=True)
    print(json.dumps(tally, indent=1))
    if len(diff) > 2:
        dq = np.array(diff)
        mu, sd = float(dq.mean()), float(dq.std(ddof=1))
        print(f"q_{rival_id} - q_{true_id} over {dq.size} draws: mean {mu:.2f}, sd {sd:.2f} "
              f"(the margin's model: sd {MARGIN_SD_PER_ROOT * np.sqrt(max(-mu, 0.0)):.2f}); "
              f"≥ {by_fit.MARGIN:.3g}: {int(np.sum(dq >= by_fit.MARGIN))}/{dq.size}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
