"""Simulated campaign duration: our stability decision vs the seed's fixed 1-hour soak.

Runs the full −40…60 °C Table-1 campaign through the real stacks (simulated
rig over loopback Modbus/serial, engine, SQLite, calibration core) in virtual
time, once per soak policy and simulated sensor, and compares

* simulated campaign duration and total soak time, and
* held-out accuracy: the fitted model applied to noise-free readings of the
  simulator's *true* sensor at 60 directions (Fibonacci sphere, not the
  Table 1 set) and die temperatures between the setpoints; rms vector
  error in µg, pooled over the sensors.

**Equal held-out accuracy** means: the policy's pooled held-out error is at
most ``EQUAL_ACCURACY`` (1.05) × the fixed hour's. Two things make that
comparison meaningful rather than a coin toss:

* several sensors (``--seeds``), not one: one sensor's held-out error moves
  by ±10 % with the noise realisation alone;
* common random numbers: the accelerometer and temperature-channel noise of a
  position capture is drawn from a stream keyed by (sensor, orientation,
  setpoint, attempt), so every policy measures each position of each step with
  the *same* noise whatever order it visits them in, and differences come from
  the soak alone (the soak's die probes keep the rig's stream). Keyed by the
  capture's index instead (before issue 12's soak12 branch), two policies whose
  steps visit the positions in different orders (``rate_gain: measured`` starts
  every step from home) gave each position another noise draw.

``--noise-free`` switches the accelerometer noise off: the held-out error is
then the soak-induced (systematic) part only. ``--rate-ug-per-c-per-min K``
adds the ``temperature_rate`` effect of docs/effects.md (output ∝ dT/dt
of the die, gains up to K µg per °C/min per axis), which the rig simulator
does not model on its own; the die rate is the simulated die's instantaneous
rate at the capture.

"measured k, corrected" is the engine's ``rate_gain: "measured"``: every soak at
home, the rate gain k measured from the campaign's own soak probes
(``service.engine.rate_gain``) at every poll, the calibration subtracting
k̂·dT/dt from the rows, and the soak waiting only for what that correction may
get wrong. ``--variants 1,4`` runs a subset (the fixed hour always runs: it is
the reference).

Usage: .venv/bin/python benchmarks/bench_soak_time.py [--seeds 1-8] [--fast] [--jobs N]
                                                      [--noise-free] [--rate-ug-per-c-per-min K]
                                                      [--variants 1,2,3,4]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import tempfile
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration.schedules import sphere
from drivers.clock import VirtualClock
from service.db.session import make_session_factory, upgrade_database
from service.demo import SETPOINTS_C, _create_campaign, demo_spec
from service.engine import store
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner
from simulators.truth import SensorTruth

EQUAL_ACCURACY = 1.05  # pooled held-out error ≤ this × the fixed hour's counts as equal
VARIANTS: dict[str, dict[str, Any]] = {
    "fixed 60 min (seed)": {"stability": "fixed"},
    "predictive (default)": {"stability": "predictive"},  # gradient_lag_s 10 s
    # No rate sensitivity beyond the die temperature (what the rig simulator models).
    "predictive, lag 0 s": {"stability": "predictive", "gradient_lag_s": 0.0},
    # A sensor with the catalogue's temperature_rate gain k = 100 µg per °C/min:
    # gradient_lag_s = 60 s/min · k / tempco = 60 · 100 / 150 = 40 s.
    "predictive, lag 40 s": {"stability": "predictive", "gradient_lag_s": 40.0},
    # The engine measures k from its soak probes (every soak at home) and the calibration
    # corrects k̂·rate (rate_gain "measured"); 250-sample probes so the estimate is useful
    # (not 200: a capture of the position size would be taken for a position's, see BenchTruth).
    "measured k, corrected": {"stability": "predictive", "rate_gain": "measured",
                              "soak_probe_samples": 250},
    # The same with a Williams design per plateau: every position in every slot of the sweep
    # once over the steps, so what depends on the slot (the die still approaching) is averaged
    # over the steps instead of meeting the same position at every step.
    "measured k, balanced order": {"stability": "predictive", "rate_gain": "measured",
                                   "soak_probe_samples": 250, "position_order": "balanced"},
}
RATE_PATTERN = np.array([1.0, -0.6, 0.4])  # per-axis signs/sizes of the rate effect


@dataclass
class BenchTruth(SensorTruth):
    """The simulator's sensor with keyed noise streams and an optional rate effect."""

    crn_seed: int = 0
    probe_n: int = 8  # captures of this size are soak probes (rig's own noise stream)
    rate_g_per_c_per_s: np.ndarray | None = None
    chamber: Any = None  # the rig's ChamberPhysics, set by run_campaign (exact die rate)
    _captures: int = field(default=0, init=False)
    # attempts per (orientation, setpoint): a quality re-measure gets its own stream
    _attempts: dict[tuple[int, ...], int] = field(default_factory=dict, init=False)
    _temp_rng: np.random.Generator | None = field(default=None, init=False)
    _last: tuple[float, float] | None = field(default=None, init=False)
    # Every position capture's key and noise-free mean output (ideal + rate effect at the
    # capture's die temperature and rate), g: the soak-induced part of each stored row
    # (bench_heldout_steps.py refits the rows without the accelerometer noise).
    noise_free_log: list[tuple[list[int], list[float]]] = field(default_factory=list,
                                                                init=False)

    def sample_g(self, ref_g: np.ndarray, die_c: float, n: int, rng: np.random.Generator,
                 t_s: float = 0.0, lab_to_sensor: np.ndarray | None = None) -> np.ndarray:
        rate = 0.0
        if self.chamber is not None:
            # The die's instantaneous rate: it follows the air first-order (ChamberPhysics).
            rate = (self.chamber.air_c - self.chamber.die_c) / self.chamber.die_tau_s
        elif self._last is not None and 0.0 < t_s - self._last[0] <= 300.0:
            rate = (die_c - self._last[1]) / (t_s - self._last[0])
        self._last = (t_s, die_c)
        self._temp_rng = None
        if n != self.probe_n:
            key = self._capture_key(ref_g)
            rng = np.random.default_rng(key)
            self._temp_rng = np.random.default_rng([*key, 1])
        out = super().sample_g(ref_g, die_c, n, rng, t_s, lab_to_sensor)
        effect = (np.zeros(3) if self.rate_g_per_c_per_s is None
                  else rate * self.rate_g_per_c_per_s)
        if n != self.probe_n:
            ideal = self.ideal_raw_g(np.asarray(ref_g, float)[None, :], die_c)[0] + effect
            self.noise_free_log.append((key, ideal.tolist()))
        return out + effect[None, :]

    def _capture_key(self, ref_g: np.ndarray) -> list[int]:
        """The noise stream of a position capture: (sensor, orientation, setpoint, attempt).

        Keyed by what is measured, not by when, so every policy draws the same noise for
        the same position of the same step even when it visits the positions in another
        order. Without the rig's chamber (no setpoint known): the capture's index.
        """
        if self.chamber is None:
            self._captures += 1
            return [self.crn_seed, self._captures]
        # Table-1 references are 0, ±1, ±0.707…: two decimals tell every position apart.
        pose = tuple(int(round(float(v) * 100.0)) + 200 for v in np.ravel(ref_g)[:3])
        where = (*pose, int(round(float(self.chamber.setpoint_c))) + 1000)
        attempt = self._attempts.get(where, 0)
        self._attempts[where] = attempt + 1
        return [self.crn_seed, *where, attempt, 7]

    def temperature_samples_c(self, die_c: float, n: int,
                              rng: np.random.Generator) -> np.ndarray:
        return super().temperature_samples_c(die_c, n, self._temp_rng or rng)


def make_truth(seed: int, noise_free: bool, rate_ug_per_c_per_min: float,
               probe_n: int = 8) -> BenchTruth:
    base = SensorTruth.adxl355_typical(seed)
    rate = None
    if rate_ug_per_c_per_min:
        rate = RATE_PATTERN * rate_ug_per_c_per_min * 1e-6 * 60.0  # g per °C/s
    return BenchTruth(coeffs=base.coeffs, temp_offset_c=base.temp_offset_c,
                      noise_density_ug_rthz=0.0 if noise_free else base.noise_density_ug_rthz,
                      crn_seed=seed, rate_g_per_c_per_s=rate, probe_n=probe_n)


@contextlib.contextmanager
def catching_chamber(truths: Iterable[SensorTruth]) -> Iterator[None]:
    """Hand the next simulated rig's chamber to every BenchTruth among ``truths``.

    The rig simulator keeps its physics to itself; catch its chamber so the rate effect uses
    the die's true instantaneous rate (consecutive captures can be a ramp apart). The sensors
    of one rig share its chamber, so one chamber serves N truths.
    """
    import simulators.rig as sim_rig

    physics = sim_rig.ChamberPhysics
    bench = [t for t in truths if isinstance(t, BenchTruth)]

    def _caught(*a: Any, **kw: Any) -> Any:
        chamber = physics(*a, **kw)
        for t in bench:
            t.chamber = chamber
        return chamber

    sim_rig.ChamberPhysics = _caught  # type: ignore[misc, assignment]
    try:
        yield
    finally:
        sim_rig.ChamberPhysics = physics  # type: ignore[misc]


async def run_campaign(spec: dict[str, Any], db_dir: Path, seed: int,
                       truth: SensorTruth) -> tuple[Any, float, list[dict]]:
    url = f"sqlite:///{db_dir / 'bench.db'}"
    upgrade_database(url)
    sf = make_session_factory(url)
    store.fast_sqlite_commits(sf)
    cid = _create_campaign(sf, spec)
    clock = VirtualClock(idle_wall_s=0.0003)
    with catching_chamber([truth]):
        async with open_rig({"name": "sim", "chamber": {"driver": "sim"}}, clock, seed=seed,
                            sim_options={"truth": truth}) as dev:
            runner = CampaignRunner(sf, cid, dev, clock)
            state = await runner.run()
    camp = store.load_campaign(sf, cid)
    if state != "completed":
        raise RuntimeError(f"campaign {state}: {camp.error}")
    return runner.fit_result, clock.now(), camp.steps_log


def heldout_errors_g(model: Any, truth: SensorTruth, temps_die_c: np.ndarray) -> np.ndarray:
    """Vector errors (g) of the model on the true sensor, static, at held-out points."""
    refs = sphere(60)
    errs = []
    for die_c in temps_die_c:
        raw = truth.ideal_raw_g(refs, die_c)
        out = model.compensate(raw, die_c + truth.temp_offset_c, extrapolate=True)
        errs.append(np.linalg.norm(out - refs, axis=1))
    return np.concatenate(errs)


def heldout_rmse_ug(model: Any, truth: SensorTruth, temps_die_c: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(heldout_errors_g(model, truth, temps_die_c))))) * 1e6


def one_case(args: tuple[str, int, bool, bool, float, dict[str, Any]]) -> dict[str, Any]:
    """One campaign (variant × sensor); runs in a worker process."""
    name, seed, fast, noise_free, rate, extra = args
    # Probes keep the rig's noise stream, so every variant measures positions with the same noise.
    truth = make_truth(seed, noise_free, rate,
                       int(VARIANTS[name].get("soak_probe_samples", 8)))
    sp = demo_spec(fast)["setpoints_c"] if fast else SETPOINTS_C
    temps = np.arange(sp[0] + 5.0, sp[-1], 10.0)
    w0 = time.monotonic()
    with tempfile.TemporaryDirectory() as d:
        fit, sim_s, log = asyncio.run(run_campaign({**demo_spec(fast), **VARIANTS[name], **extra},
                                                   Path(d), seed, truth))
    err = heldout_errors_g(fit.model, make_truth(seed, noise_free, rate), temps)
    return {
        "name": name, "seed": seed, "sim_s": sim_s, "soak_s": sum(e["soak_s"] for e in log),
        "sq_err": float(np.sum(err**2)), "n_err": int(err.size),
        "rmse_ug": float(np.sqrt(np.mean(err**2))) * 1e6,
        "max_soak": sum(bool(e.get("max_soak_reached")) for e in log),
        "valid_c": list(fit.model.valid_c or ()), "wall_s": time.monotonic() - w0,
        "k_used": [e.get("rate_gain_ug_per_c_per_min") for e in log
                   if e.get("rate_gain_ug_per_c_per_min") is not None],
    }


def parse_seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-8", help="simulated sensors, e.g. 1-8 or 1,3,5")
    ap.add_argument("--fast", action="store_true", help="3 steps instead of 11")
    ap.add_argument("--jobs", type=int, default=min(4, os.cpu_count() or 1))
    ap.add_argument("--noise-free", action="store_true",
                    help="no accelerometer noise: held-out error = soak-induced part only")
    ap.add_argument("--rate-ug-per-c-per-min", type=float, default=0.0,
                    help="add the temperature_rate effect with this largest per-axis gain")
    ap.add_argument("--variants", default="",
                    help="comma-separated numbers of the policies to run besides the fixed "
                         f"hour (1-{len(VARIANTS) - 1}, in the order {list(VARIANTS)[1:]})")
    ap.add_argument("--extra", default="{}",
                    help='spec keys (JSON) added to every policy, the fixed hour\'s too, e.g. '
                         '\'{"step_tol_c": 2.0}\' or a position_order')
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    extra = json.loads(args.extra)
    names = list(VARIANTS)
    if args.variants:
        names = [names[0]] + [names[int(i)] for i in args.variants.split(",")]
    cases = [(name, s, args.fast, args.noise_free, args.rate_ug_per_c_per_min, extra)
             for name in names for s in seeds]
    w0 = time.monotonic()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(one_case, cases))
    print(f"{len(seeds)} sensors (seeds {args.seeds}), "
          f"{'noise-free accelerometer' if args.noise_free else 'simulated noise'}"
          + (f", temperature_rate {args.rate_ug_per_c_per_min:g} µg per °C/min"
             if args.rate_ug_per_c_per_min else "")
          + f"; {time.monotonic() - w0:.0f} s wall\n")
    summary = {}
    for name in names:
        rs = [r for r in results if r["name"] == name]
        summary[name] = {
            "sim_s": np.mean([r["sim_s"] for r in rs]),
            "soak_s": np.mean([r["soak_s"] for r in rs]),
            "rmse_ug": 1e6 * float(np.sqrt(sum(r["sq_err"] for r in rs)
                                          / sum(r["n_err"] for r in rs))),
            "per_seed": {r["seed"]: r for r in rs}, "max_soak": sum(r["max_soak"] for r in rs),
        }
        if rs and rs[0]["k_used"]:
            ks = np.array([r["k_used"] for r in rs])
            print(f"{name}: k fed per step (µg per °C/min, mean over sensors): "
                  + " ".join(f"{v:.0f}" for v in ks.mean(axis=0)))
    print(f"{'policy':<24} {'campaign':>9} {'soak':>8} {'held-out':>9}  max-soak steps")
    for name, s in summary.items():
        print(f"{name:<24} {s['sim_s'] / 3600:7.2f} h {s['soak_s'] / 3600:6.2f} h "
              f"{s['rmse_ug']:7.2f} µg  {s['max_soak']}")
    base = summary[names[0]]
    if args.noise_free:
        print("\nsoak-induced held-out error only (diagnostic, no verdict): compare it with "
              "the total held-out error of a run with noise")
    else:
        print(f"\nrelative to the fixed soak (equal accuracy: held-out ≤ ×{EQUAL_ACCURACY:.2f}):")
    for name, s in list(summary.items())[1:]:
        paired = [s["per_seed"][k]["rmse_ug"] / base["per_seed"][k]["rmse_ug"] for k in seeds]
        spread = float(np.std(paired, ddof=1)) if len(paired) > 1 else 0.0
        ratio = s["rmse_ug"] / base["rmse_ug"]
        verdict = "equal" if ratio <= EQUAL_ACCURACY else "LESS ACCURATE"
        if args.noise_free:
            verdict = ""
        print(f"  {name:<24} campaign ×{s['sim_s'] / base['sim_s']:.2f}  "
              f"soak ×{s['soak_s'] / base['soak_s']:.2f}  held-out ×{ratio:.3f} "
              f"(per sensor {np.mean(paired):.3f} ± {spread:.3f}, worst {max(paired):.3f})"
              f"  {verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
