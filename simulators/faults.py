"""Fault injection switches for the simulated devices; mutate the instance at run time."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class SimFaults:
    """Per-device fault probabilities (per request) and stuck states.

    One instance per simulated device; the servers read it on every request,
    so a test or the CLI can flip a field while the rig is running.
    """

    p_exception: float = 0.0  # answer with a protocol exception (Modbus: DEVICE_BUSY)
    p_no_reply: float = 0.0  # swallow the reply: the client times out
    p_drop: float = 0.0  # close the connection instead of replying
    stuck_process_value: bool = False  # chamber: PV frozen at its value when set
    never_in_position: bool = False  # table: arrives but never reports in-position
