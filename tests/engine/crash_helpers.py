"""What the crash and stall tests share: a worker process running one campaign over the
simulated rig, and the measurements it stored
(counted with ``engine_helpers.n_measurements``)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

WORKER = Path(__file__).with_name("crash_worker.py")
ROOT = Path(__file__).resolve().parents[2]
# A fixed soak: what these tests guard (the lease, the cursor, no row lost or doubled
# across processes) does not depend on the soak's rule, and a predictive soak probes the
# dies at every poll (a third of a worker's CPU here). tests/engine/test_runner.py resumes
# predictive soaks.
SPEC = {"setpoints_c": [0.0, 20.0, 40.0], "soak_min": 20, "stability": "fixed",
        "positions": "table1", "samples_per_position": 50, "ramp_c_per_min": 2.0}
N_STEPS, N_POS = 3, 24


def start_worker(url: str, cid: int) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, str(WORKER), url, str(cid), "1.5"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
