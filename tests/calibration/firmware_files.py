"""The parameter files ``soakcal export`` writes, read back as the firmware reads them: a
PX4 ``.params`` file (QGroundControl's tab-separated vehicle, component, name, value,
type) and an ArduPilot ``.param`` file (name,value). Shared by the export tests and the
firmware-flight tests, which each implement the firmware's formula themselves."""

from __future__ import annotations


def px4_params(text: str) -> dict[str, float]:
    """name → value of a PX4 parameter file (comment lines start with '#')."""
    out = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            _veh, _comp, name, value, _type = line.split("\t")
            out[name] = float(value)
    return out


def ardupilot_params(text: str) -> dict[str, float]:
    """name → value of an ArduPilot parameter file (comment lines start with '#')."""
    return {n: float(v) for n, v in (line.split(",") for line in text.splitlines()
                                      if line and not line.startswith("#"))}
