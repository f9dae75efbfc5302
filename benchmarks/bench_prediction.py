"""How close is the door's ``predicted_duration_s`` to a real campaign on the twin?

Runs a few campaigns through the full stack (simulated chamber, turntable and
sensor over loopback Modbus/serial, the campaign engine, the fit) in virtual
time, as ``soakcal demo`` does, and compares the simulated duration with
``service.dry_run.predicted_duration_s`` of the same spec.

    .venv/bin/python benchmarks/bench_prediction.py
"""

from __future__ import annotations

import asyncio
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from drivers.clock import VirtualClock  # noqa: E402
from service.db.models import Campaign, Rig  # noqa: E402
from service.db.session import make_session_factory, upgrade_database  # noqa: E402
from service.dry_run import predicted_duration_s, schedule_verdict  # noqa: E402
from service.engine import store  # noqa: E402
from service.engine.rigs import open_rig  # noqa: E402
from service.engine.runner import CampaignRunner  # noqa: E402
from service.engine.spec import EngineSpec  # noqa: E402

SPECS: dict[str, dict[str, Any]] = {
    "3 steps, fixed 30 min, six, 100 samples": {
        "setpoints_c": [-20.0, 10.0, 40.0], "soak_min": 30, "stability": "fixed",
        "positions": "six", "samples_per_position": 100, "ramp_c_per_min": 2.0},
    "3 steps, predictive 60 min, table1, 200 samples": {
        "setpoints_c": [-40.0, 10.0, 60.0], "soak_min": 60, "stability": "predictive",
        "positions": "table1", "samples_per_position": 200, "ramp_c_per_min": 2.0},
    "5 steps, dwell 20 min, cube14, 50 samples": {
        "setpoints_c": [-30.0, -10.0, 10.0, 30.0, 50.0], "soak_min": 20, "stability": "dwell",
        "positions": "cube14", "samples_per_position": 50, "ramp_c_per_min": 1.0},
}


async def _run(spec: dict[str, Any], workdir: Path) -> float:
    url = f"sqlite:///{workdir / 'bench.db'}"
    upgrade_database(url)
    sf = make_session_factory(url)
    store.fast_sqlite_commits(sf)
    with sf() as s:
        s.add(Rig(name="sim", chamber={"driver": "sim", "range_c": [-70.0, 180.0]},
                  turntable={"driver": "sim"}, sensors=[{"driver": "sim"}]))
        s.flush()
        c = Campaign(rig="sim", sensor="SN-BENCH", spec=spec, state="queued", progress={},
                     steps_log=[])
        s.add(c)
        s.commit()
        cid = c.id
    clock = VirtualClock(idle_wall_s=0.0003)
    async with open_rig({"name": "sim", "chamber": {"driver": "sim"}}, clock, seed=1) as dev:
        state = await CampaignRunner(sf, cid, dev, clock).run()
    sf.kw["bind"].dispose()
    if state != "completed":
        raise RuntimeError(f"campaign ended {state}")
    return clock.now()


def main() -> int:
    print(f"{'campaign':48s} {'predicted':>10s} {'simulated':>10s} {'error':>7s}  wall")
    errors = []
    for name, spec in SPECS.items():
        model = EngineSpec.model_validate(spec)
        n_positions, why = schedule_verdict(model.positions, "reference")
        assert why is None and n_positions is not None
        predicted_s = predicted_duration_s(model)
        wall0 = time.monotonic()
        with tempfile.TemporaryDirectory() as tmp:
            simulated_s = asyncio.run(_run(spec, Path(tmp)))
        err = (predicted_s - simulated_s) / simulated_s * 100.0
        errors.append(abs(err))
        print(f"{name:48s} {predicted_s / 3600:8.2f} h {simulated_s / 3600:8.2f} h "
              f"{err:+6.1f} %  {time.monotonic() - wall0:4.0f} s")
    print(f"largest |error| {max(errors):.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
