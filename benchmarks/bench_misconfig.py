"""``rig check --move`` against a twin configured unlike its map: is each misconfiguration
caught, with its cause named, at several chamber temperatures?

    .venv/bin/python benchmarks/bench_misconfig.py [--temps 23,-20,60,3]

For every case the twin's chamber controller is set up as a lab's controller
might be (``simulators.chamber_sim.ControllerSetup``: decimal point, °F,
per-hour ramp, swapped words, a missing register, manual, standby) or the
map is wrong (PV at an address where this controller has nothing), the rig
starts at the given temperature (air and die settled there), and
``service.rig_check.check_rig(move=True)`` runs in this process in simulated
time over Modbus TCP on loopback. A case counts as *caught* when a chamber
check fails and its detail or fix contains the case's cause words; *missed* when
every check passes or is skipped; *wrong cause* when something fails for
another reason. ``SP kept`` says the controller's setpoint (in °C, physics
truth) is where it was after the check.
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from drivers.clock import VirtualClock
from service.rig_check import Check, check_rig
from simulators.chamber_sim import ControllerSetup
from simulators.rig import start_sim_rig


@dataclass(frozen=True)
class Case:
    name: str
    setup: ControllerSetup
    chamber_map: str  # the controller's true layout (what the twin serves)
    cause: str  # words the failing check's detail must contain ("" = must pass)
    lab_map: str = ""  # the map the rig check reads it with (default: the true one)


#: The 3216 read through its 16-bit integer region (decimal point implied by the display
#: setting): the layout a decimal-point misconfiguration mis-scales. The shipped map reads
#: the IEEE float region and is immune (its row shows it).
INT16_3216 = str(Path(__file__).resolve().parents[1] / "tests" / "drivers" / "data"
                 / "eurotherm-3216-int16.toml")
MAPS = Path(__file__).resolve().parents[1] / "drivers" / "maps"


def _wrong_pv_map(tmp: Path) -> str:
    text = Path(INT16_3216).read_text()
    path = tmp / "lab-3216-pv-at-4.toml"
    path.write_text(text.replace("[registers.process_c]\naddress = 1\n",
                                 "[registers.process_c]\naddress = 4\n"))
    return str(path)


def _ezt_fc16_map(tmp: Path) -> str:
    """The EZT-430i map with its setpoint written by FC 16, which the controller ignores."""
    path = tmp / "lab-ezt-fc16.toml"
    path.write_text((MAPS / "csz-ezt-430i.toml").read_text().replace(
        'write = "single"', 'write = "multiple"'))
    return str(path)


def _f4_no_sequence_map(tmp: Path) -> str:
    """The F4 map without its [[sequence.set_setpoint]] (the setpoint written alone)."""
    head, _, rest = (MAPS / "watlow-f4.toml").read_text().partition("# Every setpoint change")
    path = tmp / "lab-f4-no-sequence.toml"
    path.write_text(head + rest[rest.index("[registers.process_c]"):])
    return str(path)


def cases(tmp: Path) -> list[Case]:
    return [
        Case("as the map says (control)", ControllerSetup(), "eurotherm-3216", ""),
        Case("whole degrees, map tenths (×10)", ControllerSetup(decimals=0), INT16_3216, "×10"),
        Case("hundredths, map tenths (×0.1)", ControllerSetup(decimals=2), INT16_3216, "×0.1"),
        Case("whole degrees, shipped float map", ControllerSetup(decimals=0),
             "eurotherm-3216", ""),
        Case("units °F", ControllerSetup(units="F"), "eurotherm-3216", "°F"),
        # A 3216 set to per-hour ramps shows it in RAMP.U (1) too.
        Case("ramp per hour", ControllerSetup(ramp_per="hour", holds=(("ramp_units", 1.0),)),
             "eurotherm-3216", "per hour"),
        Case("ramp per hour, RAMP.U not mapped", ControllerSetup(ramp_per="hour"),
             INT16_3216, "per hour"),
        Case("float words swapped (F4T)", ControllerSetup(swap_words=True), "watlow-f4t",
             "swapped"),
        Case("PV register points elsewhere", ControllerSetup(), INT16_3216,
             "`address` of register `process_c`", lab_map=_wrong_pv_map(tmp)),
        Case("alarm register absent", ControllerSetup(silent=frozenset({"alarms"})),
             "eurotherm-3216", "does not answer"),
        Case("controller in manual", ControllerSetup(mode="manual"), "eurotherm-3216",
             "manual"),
        Case("F4T loop 1 in manual", ControllerSetup(holds=(("loop_mode", 54.0),)),
             "watlow-f4t", "manual"),
        Case("controller in standby", ControllerSetup(mode="standby"), "eurotherm-3216",
             "standby"),
        # Controllers without a working setpoint or a static ramp (absent_roles).
        Case("EZT-430i as the map says (control)", ControllerSetup(), "csz-ezt-430i", ""),
        Case("EZT-430i whole degrees (×10)", ControllerSetup(decimals=0), "csz-ezt-430i",
             "×10"),
        Case("EZT-430i in °F", ControllerSetup(units="F"), "csz-ezt-430i", "°F"),
        # No run register, no WSP, no ramp: nothing the check reads tells standby apart.
        Case("EZT-430i in standby", ControllerSetup(mode="standby"), "csz-ezt-430i",
             "standby"),
        Case("EZT-430i, map writes SP by FC 16", ControllerSetup(single_writes_only=True),
             "csz-ezt-430i", 'write = "single"', lab_map=_ezt_fc16_map(tmp)),
        Case("F4 as the map says (control)", ControllerSetup(), "watlow-f4", ""),
        Case("F4 running a profile, map without the sequence",
             ControllerSetup(profile_owns_setpoint=("terminate_profile", 1.0),
                             holds=(("profile_status", 2.0),)),
             "watlow-f4", "profile", lab_map=_f4_no_sequence_map(tmp)),
        Case("F4 in °F", ControllerSetup(units="F", holds=(("units", 0.0),)), "watlow-f4",
             "°F"),
    ]


async def run_case(case: Case, start_c: float) -> tuple[str, str, bool, float]:
    clock = VirtualClock()
    t0 = time.perf_counter()
    async with start_sim_rig(clock, seed=4, chamber_map=case.chamber_map,
                             controller=case.setup, start_c=start_c) as sim:
        sp_before = sim.chamber.setpoint_c
        rig = {"name": "bench",
               "chamber": {"driver": "modbus", "url": sim.chamber_url,
                           "map": case.lab_map or case.chamber_map},
               "turntable": {"url": sim.table_url, "map": sim.table_map},
               "sensors": [{"url": sim.sensor_url}]}
        checks = await check_rig(rig, move=True, clock=clock)
        kept = abs(sim.chamber.setpoint_c - sp_before) < 1e-6
    return (*_verdict(case, checks), kept, time.perf_counter() - t0)


def _verdict(case: Case, checks: list[Check]) -> tuple[str, str]:
    failed = [c for c in checks if c.status == "fail"]
    skipped = [f"{c.device}.{c.check}" for c in checks
               if c.status == "skip" and c.check == "pv_vs_die"]
    if not case.cause:  # a controller the map reads right: nothing may fail
        return ("passed" if not failed else "false alarm",
                "; ".join(f"{c.check}: {c.detail}" for c in failed) or ", ".join(skipped))
    hit = next((c for c in failed if case.cause in f"{c.detail} {c.fix}"), None)
    if hit is not None:
        return "caught", f"{hit.check}: {hit.detail}"
    if failed:
        return "wrong cause", f"{failed[0].check}: {failed[0].detail}"
    if skipped:
        return "not caught (pv_vs_die skipped: too near 0 °C to tell)", ""
    return "missed", "every check passed"


async def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--temps", default="23,-20,60,3",
                    help="chamber temperatures to start at, °C (comma-separated)")
    args = ap.parse_args()
    temps = [float(t) for t in args.temps.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        all_cases = cases(Path(tmp))
        controls = {c.name for c in all_cases if not c.cause}
        for case in all_cases:
            for start_c in temps:
                verdict, why, kept, wall_s = await run_case(case, start_c)
                rows.append((case.name, start_c, verdict, kept, wall_s, why))
    # The pivot (what docs/benchmarks.md shows), then every run with the cause it named.
    names = list(dict.fromkeys(r[0] for r in rows))
    print("| misconfiguration | " + " | ".join(f"{t:g} °C" for t in temps) + " | check |")
    print("|---|" + "---|" * len(temps) + "---|")
    for name in names:
        mine = [r for r in rows if r[0] == name]
        check = next((r[5].split(": ", 1)[0] for r in mine if r[2] == "caught"), "")
        print(f"| {name} | " + " | ".join(r[2] + ("" if r[3] else ", SP moved")
                                          for r in mine) + f" | {check} |")
    print()
    print("| misconfiguration | chamber °C | verdict | SP kept | wall s | check: cause named |")
    print("|---|---|---|---|---|---|")
    for name, start_c, verdict, kept, wall_s, why in rows:
        print(f"| {name} | {start_c:g} | {verdict} | {'yes' if kept else 'NO'} | "
              f"{wall_s:.2f} | {why.replace('|', '/')} |")
    wanted = [r for r in rows if r[0] not in controls]
    caught = sum(r[2] == "caught" for r in wanted)
    print(f"\ncaught {caught}/{len(wanted)} misconfigured runs; control runs: "
          + ", ".join(r[2] for r in rows if r[0] in controls))


if __name__ == "__main__":
    asyncio.run(main())
