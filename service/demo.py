"""``soakcal demo``: one complete simulated campaign, end to end, in accelerated time.

``--method ramp``: the ramp method instead (calibration/ramp_plan.py, docs/ramp-campaigns.md):
the chamber ramps through the range and back while the table sweeps, and the recording
is fitted continuously in each capture's die temperature.

The real stacks all run: the simulated chamber and turntable as Modbus TCP
servers on loopback, the simulated ADXL355 behind the serial bridge protocol,
the drivers, the campaign engine (ramp, stability-decided soak, 24 positions
× 200 samples per step, every measurement committed before the next move),
an embedded SQLite database, then the calibration core (per-step SFEM fits
and the cubic thermal model) and its report. Only time is virtual
(:class:`drivers.clock.VirtualClock`): a ~15 h campaign takes seconds.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import time
from pathlib import Path
from typing import Any

from drivers.clock import VirtualClock
from service.db.models import Campaign, Rig
from service.db.session import make_session_factory, upgrade_database
from service.engine import store
from service.engine.rigs import open_rig
from service.engine.runner import CampaignRunner

SETPOINTS_C = [-40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0]
FAST_SETPOINTS_C = [-40.0, 10.0, 60.0]
SENSOR_SERIAL = "SN-DEMO-0001"
# The clock watches the event loop and the bridge's port threads (VirtualClock(idle="loop"):
# no wall-time window before a jump); a real-time timer due within this is still waited for.
IDLE_WALL_S = 0.0003


MAX_DEMO_SENSORS = 64  # the campaign contract's limit (service/api/schemas.py)


def sensors_count(text: str) -> int:
    """``--sensors N``: an integer 1…64 (argparse type: a bad value is a one-line exit 2)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer 1…{MAX_DEMO_SENSORS}, "
                                         f"got {text!r}") from None
    if not 1 <= n <= MAX_DEMO_SENSORS:
        raise argparse.ArgumentTypeError(f"expected 1…{MAX_DEMO_SENSORS} sensors, got {n}")
    return n


def demo_serials(n: int) -> list[str]:
    """The demo fixture's serials: the one-sensor demo's serial first, then SN-DEMO-0002…"""
    return [SENSOR_SERIAL] + [f"SN-DEMO-{i:04d}" for i in range(2, n + 1)]


def run_demo(args: argparse.Namespace) -> int:
    """Entry point of ``soakcal demo [--method soak|ramp] [--out DIR] [--fast] [--sensors N]``."""
    out = Path(getattr(args, "out", None) or "soakcal-demo")
    fast = bool(getattr(args, "fast", False))
    spec = ramp_demo_spec(fast) if getattr(args, "method", None) == "ramp" else demo_spec(fast)
    n_sensors = int(getattr(args, "sensors", 1) or 1)
    if n_sensors > 1:
        spec["sensors"] = demo_serials(n_sensors)
    order = getattr(args, "position_order", None)
    if order:  # absent: the engine's default (travel)
        spec["position_order"] = str(order)
    return asyncio.run(_demo(out, spec))


def ramp_demo_spec(fast: bool = False) -> dict[str, Any]:
    """The ramp method over the seed's range: −40 → 60 °C and back at 3 °C/min, Table 1
    swept over and over, 200 samples per capture (docs/ramp-campaigns.md); ``fast``: a
    narrow range (0…30 °C)."""
    return {
        "method": "ramp",
        "setpoints_c": [0.0, 30.0] if fast else [-40.0, 60.0],
        "soak_min": 60,
        "positions": "table1",
        "samples_per_position": 200,
        "ramp_c_per_min": 3.0,
    }


def demo_spec(fast: bool = False) -> dict[str, Any]:
    """The seed's protocol: −40…60 °C in 10 °C steps, ~1 h soak, Table 1, 200 samples."""
    return {
        "setpoints_c": FAST_SETPOINTS_C if fast else SETPOINTS_C,
        "soak_min": 60,
        "positions": "table1",
        "samples_per_position": 200,
        "ramp_c_per_min": 2.0,
        "stability": "predictive",
    }


def step_line(entry: dict[str, Any], wall_s: float) -> str:
    """One progress line per finished step. The step is numbered as the recording, the
    report and the event log number it (from 0), with its place in the campaign beside it:
    "step 7 (8/11)" next to the event "soak ended step=7" (a 1-based "8/11" alone read as
    step 8 beside the event log's step=8, which is the next setpoint)."""
    tau = entry.get("tau_s")
    tau_txt = f", τ {tau / 60:.1f} min" if tau else ""
    return (f"  step {entry['step']:2d} ({entry['step'] + 1}/{entry['steps']})  "
            f"{entry['setpoint_c']:6.1f} °C  chamber {entry['chamber_c']:7.2f} °C  "
            f"soak {entry['soak_s'] / 60:5.1f} min ({entry['reason']}{tau_txt})  "
            f"[wall {wall_s:5.1f} s]")


async def _demo(out: Path, spec: dict[str, Any],
                sim_options: dict[str, Any] | None = None) -> int:
    """``sim_options``: passed to the twin (``open_rig``), e.g. ``{"multiplexed": True}`` to
    mount the sensors on one multiplexing bridge (benchmarks/bench_mux_bridge.py)."""
    wall0 = time.monotonic()
    out.mkdir(parents=True, exist_ok=True)
    db_path = out / "demo.db"
    for p in out.glob("demo.db*"):  # a fresh database each run
        p.unlink()
    url = f"sqlite:///{db_path.resolve()}"
    upgrade_database(url)
    sf = make_session_factory(url)
    store.fast_sqlite_commits(sf)
    cid = _create_campaign(sf, spec)
    n_steps = len(spec["setpoints_c"])
    ramp = spec.get("method") == "ramp"
    if ramp:
        print(f"soakcal demo: ramp {min(spec['setpoints_c']):g} → {max(spec['setpoints_c']):g} "
              f"°C and back at {spec['ramp_c_per_min']:g} °C/min, 24 positions swept over and "
              f"over × {spec['samples_per_position']} samples, simulated rig over Modbus TCP + "
              "serial on loopback, virtual time", flush=True)
    else:
        print(f"soakcal demo: {n_steps} steps {spec['setpoints_c'][0]:g}…"
              f"{spec['setpoints_c'][-1]:g} °C × 24 positions × {spec['samples_per_position']} "
              "samples, simulated rig over Modbus TCP + serial on loopback, virtual time",
              flush=True)

    def on_step(entry: dict[str, Any]) -> None:
        print(step_line(entry, time.monotonic() - wall0), flush=True)

    clock = VirtualClock(idle_wall_s=IDLE_WALL_S, idle="loop")
    serials = list(spec.get("sensors") or [])
    async with open_rig({"name": "sim", "chamber": {"driver": "sim"}}, clock, seed=1,
                        serials=serials, sim_options=sim_options) as devices:
        runner = CampaignRunner(sf, cid, devices, clock, on_step=on_step)
        state = await runner.run()
    camp = store.load_campaign(sf, cid)
    if state != "completed":
        print(f"demo campaign ended {state}: {camp.error}")
        return 1
    sim_h = clock.now() / 3600.0
    if serials:
        return _report_several(sf, cid, camp, serials, sim_h, time.monotonic() - wall0)
    paths = _write_outputs(sf, cid, out, runner.fit_result)
    print()
    print(_table6(runner.fit_result))
    print()
    if ramp:
        print(f"campaign {cid}: ramp, {_sweeps(sf, cid)}, simulated {sim_h:.2f} h in "
              f"{time.monotonic() - wall0:.1f} s wall")
        for label, path in paths.items():
            print(f"  {label:<10} {path}")
        return 0
    soak_min = sum(e["soak_s"] for e in camp.steps_log) / 60.0
    print(f"campaign {cid}: {len(camp.steps_log)} steps, "
          f"{sum(1 for _ in store.measured_positions(sf, cid))} positions stored, "
          f"simulated {sim_h:.1f} h (soak total {soak_min:.0f} min) "
          f"in {time.monotonic() - wall0:.1f} s wall")
    if runner.guard.faults_retried or runner.guard.suspensions:
        print(f"device faults retried: {runner.guard.faults_retried}, "
              f"suspensions: {runner.guard.suspensions}")
    for label, path in paths.items():
        print(f"  {label:<10} {path}")
    return 0


def _report_several(sf: Any, cid: int, camp: Any, serials: list[str], sim_h: float,
                    wall_s: float) -> int:
    """One line per sensor: its calibration's rmse and valid range, or why it was dropped."""
    from service.db.models import Calibration

    ids = dict(camp.calibration_ids or {})
    dropped = dict(camp.sensors_dropped or {})
    with sf() as s:
        cals = {c.id: c for c in s.query(Calibration).filter(Calibration.campaign_id == cid)}
    print()
    for serial in serials:
        if serial in ids:
            cal = cals[ids[serial]]
            print(f"  {serial:<14} calibration {cal.id}: rmse {cal.rmse_ug:8.1f} µg, valid "
                  f"{cal.valid_lo_c:.1f}…{cal.valid_hi_c:.1f} °C")
        else:
            print(f"  {serial:<14} dropped: {dropped.get(serial, 'no calibration')}")
    if (camp.spec or {}).get("method") == "ramp":
        print(f"campaign {cid}: ramp, {len(serials)} sensors, {len(ids)} calibrated, "
              f"{_sweeps(sf, cid)}, simulated {sim_h:.2f} h in {wall_s:.1f} s wall")
        return 0 if ids else 1
    soak_min = sum(e["soak_s"] for e in camp.steps_log) / 60.0
    print(f"campaign {cid}: {len(serials)} sensors, {len(ids)} calibrated, "
          f"{len(camp.steps_log)} steps, "
          f"{sum(1 for _ in store.measured_positions(sf, cid))} positions stored, "
          f"simulated {sim_h:.1f} h (soak total {soak_min:.0f} min) in {wall_s:.1f} s wall")
    return 0 if ids else 1


def _sweeps(sf: Any, cid: int) -> str:
    """'N sweeps, M captures' of a ramp campaign (a sweep is one step index)."""
    stored = store.measured_positions(sf, cid)
    return f"{len({s for s, _ in stored})} sweeps, {len(stored)} captures"


def _create_campaign(sf: Any, spec: dict[str, Any]) -> int:
    with sf() as s:
        s.add(Rig(name="sim", chamber={"driver": "sim", "range_c": [-70.0, 180.0]},
                  turntable={"driver": "sim"}, sensors=[{"driver": "sim", "model": "ADXL355"}]))
        s.flush()  # no ORM relationship: the rig row must exist before the campaign's FK
        c = Campaign(rig="sim", sensor=SENSOR_SERIAL, spec=spec, state="queued", progress={},
                     steps_log=[])
        s.add(c)
        s.commit()
        return c.id


def _write_outputs(sf: Any, cid: int, out: Path, fit: Any) -> dict[str, Path]:
    """Recording CSV, model JSON, report JSON and figures; returns what went where."""
    from calibration.recording import Recording, write_recording

    cols = store.measurement_columns(sf, cid)
    rec = Recording.from_columns(cols, path=str(out / "recording.csv"))
    paths: dict[str, Path] = {"database": out / "demo.db", "recording": out / "recording.csv",
                              "model": out / "model.json", "report": out / "report.json"}
    write_recording(paths["recording"], rec)
    from service.engine.calibrate import _jsonable, model_document

    paths["model"].write_text(json.dumps(model_document(fit.model), indent=2) + "\n")
    paths["report"].write_text(json.dumps(_jsonable(fit.report), indent=2) + "\n")
    if getattr(fit.model, "method", None) == "continuous":
        return paths  # figures are drawn for step fits only (calibration/cli.py)
    try:
        from calibration.report import write_figures

        figs = write_figures(fit, rec, out / "figures")
        paths["figures"] = figs[0].parent if figs else out / "figures"
    except Exception as exc:  # figures are a bonus; the numbers are already written
        print(f"(figures not written: {exc})")
    return paths


def _table6(fit: Any) -> str:
    if getattr(fit.model, "method", None) == "continuous":  # a ramp: per temperature band
        from calibration.ramp_report import format_ramp_report

        return format_ramp_report(fit)
    try:
        from calibration.report import format_table6
    except ImportError:  # the core's report module not there: a minimal table
        rows = [f"{s.step:3d} {s.temperature_c:8.2f} {s.rmse_before_ug / 1e3:9.4f} "
                f"{s.rmse_polynomial_ug / 1e3:9.4f}" for s in fit.steps]
        return "step  T (°C)  before(mg) after(mg)\n" + "\n".join(rows)
    return format_table6(fit)
