"""The door's dry run, bounded: time and memory to refuse or plan a campaign.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_plan_bound.py

For each campaign body it runs ``service.dry_run.check_campaign`` on the built-in ``sim``
rig (what ``POST /api/v1/campaigns`` runs before anything is stored) and prints the
verdict and the wall time of its first (cold) run, then the process' peak resident
memory after all of them (``ru_maxrss``): the schedules refused for their size (more
than ``MAX_POSITIONS`` per step, or ``MAX_CAMPAIGN_POSITIONS`` over the campaign) and
the largest ones still planned.
Before the bound, ``sphere5000`` took 53 s and 3.1 GB at the door.
"""

from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CASES: list[tuple[str, dict[str, object]]] = [
    ("sphere5000 (refused)", {"positions": "sphere5000"}),
    ("sphere5000+sphere5000 (refused)", {"positions": "sphere5000+sphere5000"}),
    ("sphere65 (refused)", {"positions": "sphere65"}),
    ("table1 x 200 setpoints (refused)",
     {"positions": "table1", "setpoints_c": [float(-40 + i % 100) for i in range(200)]}),
    ("table1 x 11 setpoints (the seed)", {"positions": "table1"}),
    ("sphere64 x 11 setpoints", {"positions": "sphere64"}),
    ("sphere64 x 37 setpoints (largest accepted)",
     {"positions": "sphere64", "setpoints_c": [float(-40 + 2.5 * i) for i in range(37)]}),
]


def main() -> int:
    from service.campaigns import SIM_RIG
    from service.dry_run import check_campaign
    from service.engine.spec import EngineSpec

    check_campaign(EngineSpec(positions="six"), dict(SIM_RIG))  # imports, warm caches
    for label, body in CASES:
        spec = EngineSpec.model_validate(body)
        t0 = time.perf_counter()
        check = check_campaign(spec, dict(SIM_RIG))
        elapsed_s = time.perf_counter() - t0
        verdict = "accepted" if check.ok else "refused: " + check.issues[0].msg[:70]
        print(f"{label:<44} {elapsed_s * 1e3:9.1f} ms  {verdict}")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory of the whole run: {peak_mb:.0f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
