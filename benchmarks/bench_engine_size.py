"""The campaign engine's size and what share of it is protocol (issue 18).

Counts the lines of every function of ``service/engine/runner.py`` (from its
``def`` to its last line, docstring included) and sorts each into one job by
its name (the tables below); module-level lines (imports, constants, small
helpers) are counted apart. The protocol a reader should find in the plan,
``calibration/campaign_plan.py``, is counted beside it.

Jobs:

* ``loop`` — the engine proper: the message loop and its interpretation,
  checkpoints, pause/abort, the hold loop, progress, the commit of a save, the
  one ``finally``;
* ``verbs`` — small device steps (read or set the chamber, move, settle,
  acquire, configure, probe one poll) and the sensors' calls;
* ``checks`` — what a save checks before storing (pose, die against chamber);
* ``protocol`` — protocol written out by hand in the engine: the waits whose
  end is a decision (ramp arrival, soak), the rate gain's bookkeeping, the fit
  per sensor, and (before) the re-measure slice hidden in the save;
* ``park`` — the safe state;
* ``helpers`` — module-level functions.

The pure answers to the plan's polls (``service/engine/polls.py``: a ramp's arrival,
a soak round's decision, the dies against the chamber) are counted beside it too.

Usage (from the repository root; ``--root`` another checkout, e.g. an export of
an older commit)::

    python -m benchmarks.bench_engine_size [--root DIR]
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

JOBS: dict[str, tuple[str, ...]] = {
    "loop": (
        "__init__", "_confirm_lease", "subscribe", "run", "_start", "_execute", "_run_plan",
        "_interpret", "_held_total_s", "_active_s", "_notify", "_handlers", "_at_checkpoint",
        "_checkpoint", "_paused", "_wait_for_resume", "_lost_control", "_wait",
        "_abort_asked_recently", "_abort_asked", "_suspend", "_unsuspend", "_t", "_publish",
        "_hold", "_hold_chamber", "_resumed", "_commit", "_chamber_watched",
    ),
    "verbs": (
        "_live", "_accelerometer", "_drop", "_sensor_call", "_configure", "_configure_each",
        "_measure_one", "_measure", "_measure_live", "_move", "_settle", "_home",
        "_read_chamber", "_set_chamber", "_acquire_msg", "_acquire", "_fit", "_chamber",
        "_move_to", "_move_once", "_set_pose", "_probe_dies", "_wait_msg",
    ),
    "checks": ("_save", "_check_die_against_chamber"),
    "protocol": (
        "_ramp", "_wait_chamber", "_soak", "_no_dies", "_keep_soak", "_stored_soaks",
        "_rate_estimate", "_rate_gain_for_decision", "_rate_provenance", "_fitting",
        "_fitting_each", "_chamber_in_band", "_measure_again", "_checked_readings",
        "_save_each", "_poll_chamber", "_poll_soak",
    ),
    "park": ("_park_through_cancel", "_drive_safe", "_try_safe"),
    "helpers": ("_ref_text", "_wsp_at_target", "_clean_json", "_finite", "_soak_probes"),
}


def function_lines(path: Path) -> tuple[dict[str, int], int]:
    """Lines per function name (methods of every class, and module functions), and the
    file's total."""
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    out: dict[str, int] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            assert node.end_lineno is not None
            out[node.name] = out.get(node.name, 0) + node.end_lineno - first + 1
    return out, len(text.splitlines())


def measure(root: Path) -> dict[str, object]:
    runner, total = function_lines(root / "service" / "engine" / "runner.py")
    job_of = {name: job for job, names in JOBS.items() for name in names}
    # A method nested in another (a closure) is counted within its parent already.
    nested = {"read", "measure", "move_again", "still_tripped", "still_failing",
              "abort_point"}
    by_job: dict[str, int] = dict.fromkeys(JOBS, 0)
    unknown: dict[str, int] = {}
    for name, n in runner.items():
        if name in nested:
            continue
        job = job_of.get(name)
        if job is None:
            unknown[name] = n
        else:
            by_job[job] += n
    in_functions = sum(by_job.values()) + sum(unknown.values())
    plan_path = root / "calibration" / "campaign_plan.py"
    plan_total = len(plan_path.read_text(encoding="utf-8").splitlines())
    # The pure answers to the plan's polls, outside the engine (absent before).
    polls_path = root / "service" / "engine" / "polls.py"
    polls_total = (len(polls_path.read_text(encoding="utf-8").splitlines())
                   if polls_path.exists() else 0)
    return {"runner_lines": total, "module_level": total - in_functions, "by_job": by_job,
            "unclassified": unknown, "plan_lines": plan_total, "polls_lines": polls_total}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=".", help="checkout to measure (default: here)")
    args = ap.parse_args()
    m = measure(Path(args.root))
    total = int(m["runner_lines"])  # type: ignore[call-overload]
    print(f"runner.py: {total} lines; module level {m['module_level']}")
    for job, n in m["by_job"].items():  # type: ignore[attr-defined]
        print(f"  {job:<9} {n:5d} lines  {100.0 * n / total:5.1f} %")
    if m["unclassified"]:
        print(f"  unclassified: {m['unclassified']}")
    print(f"calibration/campaign_plan.py: {m['plan_lines']} lines")
    print(f"service/engine/polls.py: {m['polls_lines']} lines")


if __name__ == "__main__":
    main()
