"""Random protocols of the second generator: setpoints, soaks, positions, columns, rig.

Positions are two table angles (α about the inner axis, β about the outer one); the
reference is gravity seen in the sensor frame, ``ref = Rz(α)ᵀ·Rx(β)ᵀ·e_z``. A tilted table
or an encoder error changes the true force, never ``ref`` (turntable effects, effects.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SCHEDULES_DEG: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {  # (β list, α list)
    "dense24": (tuple(range(0, 360, 45)), (0.0, 90.0, 225.0)),
    "sparse18": (tuple(range(0, 360, 60)), (0.0, 90.0, 210.0)),
    "oblique36": (tuple(range(0, 360, 30)), (0.0, 45.0, 135.0)),
}
# Schedules of the "unseen" family (draw_protocol(..., family="unseen")): never drawn by the
# default family, so the blind benchmark can measure the diagnosis on positions it was not
# developed on. Product schedules (β list, α list) as above ...
UNSEEN_SCHEDULES_DEG: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    # the seed paper's 24 positions in another parametrisation: β offset by 22.5°, α at 120°
    "tri24": (tuple(22.5 + 45.0 * k for k in range(8)), (30.0, 150.0, 270.0)),
    "ring30": (tuple(range(0, 360, 36)), (0.0, 90.0, 200.0)),
    "dense48": (tuple(range(0, 360, 30)), (0.0, 60.0, 120.0, 240.0)),
    "min12": ((0.0, 90.0, 180.0, 270.0), (0.0, 45.0, 90.0)),
}
# ... and explicit (α, β) pairs: the six faces ±x ±y ±z (ref = (sinα·sinβ, cosα·sinβ, cosβ)).
UNSEEN_PAIRS_DEG: dict[str, tuple[tuple[float, float], ...]] = {
    "faces6": ((0.0, 0.0), (0.0, 180.0), (0.0, 90.0), (0.0, 270.0), (90.0, 90.0),
               (90.0, 270.0)),
}
RAMP_C_PER_MIN = 2.0
MOVE_S = 8.0
FS_HZ = 100.0


@dataclass(frozen=True)
class Protocol2:
    name: str
    setpoints_c: tuple[float, ...]
    soak_min: float
    schedule: str
    columns: tuple[str, ...]
    die_tau_s: float
    n_samples: int
    vib_sd_g: tuple[float, ...]  # per step, per-sample rms of the bench disturbance
    irregular: bool  # positions shuffled per plateau, some skipped
    power_cycle_at: int | None
    sensor_noise_g: float  # per-sample sd of the sensor's own noise
    # Defaults are the default family's rig; the "unseen" family varies them.
    placement_rad: float = 5e-6  # re-seating scatter per visit and axis (rms); mrad by hand
    sensor_c_offset_c: float = 0.0  # constant offset of the sensor_c channel
    sensor_c_lsb_c: float = 0.1  # quantisation of the sensor_c channel
    # per-sample noise of the sensor_c channel before quantisation: 0.04 °C dithers a
    # 0.1 °C LSB (capture means between codes); far below the LSB (a clean channel,
    # generate --temperature-channel clean) every reading of a settled plateau sits on one
    # code and the plateau shares that code's rounding error
    sensor_c_sd_c: float = 0.04

    def angles_deg(self) -> np.ndarray:
        if self.schedule in UNSEEN_PAIRS_DEG:
            return np.array(UNSEEN_PAIRS_DEG[self.schedule], float)
        betas, alphas = (SCHEDULES_DEG | UNSEEN_SCHEDULES_DEG)[self.schedule]
        return np.array([(a, b) for b in betas for a in alphas], float)


def rot_x(a: float | np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_z(a: float | np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def force_in_sensor(alpha_rad: float, beta_rad: float, up: np.ndarray) -> np.ndarray:
    """Specific force in the sensor frame for table angles and lab 'up' (unit, in g)."""
    return rot_z(alpha_rad).T @ rot_x(beta_rad).T @ up


KINDS = ("oneway", "updown", "irregular", "sparse", "staircase_down")


def draw_protocol(rng: np.random.Generator, kind: str | None = None,
                  schedule: str | None = None, columns: tuple[str, ...] | None = None,
                  soak_min: float | None = None, family: str = "default") -> Protocol2:
    """A random protocol. ``family="unseen"`` draws the variants of ``unseen.py`` (which
    the default family never draws); the default family's draws are unchanged by it."""
    if family == "unseen":
        from benchmarks.blind.gen2.unseen import draw_unseen
        return draw_unseen(rng, kind, schedule, columns, soak_min)
    if family != "default":
        raise ValueError(f"unknown protocol family {family!r} (default, unseen)")
    kind = kind or str(rng.choice(KINDS))
    lo = float(rng.choice([-40.0, -30.0, -20.0]))
    hi = float(rng.choice([50.0, 60.0, 70.0]))
    n_t = int(rng.integers(6, 12))
    up = tuple(float(x) for x in np.round(np.linspace(lo, hi, n_t)))
    if kind == "oneway":
        sp = up
    elif kind == "staircase_down":
        sp = up[::-1]
    elif kind == "updown":
        sp = up + up[-2::-1]
    elif kind == "irregular":
        sp = tuple(float(x) for x in rng.permutation(up))
    else:  # sparse: few temperatures
        sp = tuple(float(x) for x in np.round(np.linspace(lo, hi, 5)))
    cols = columns or [("sensor_c",), ("chamber_c", "sensor_c"), ("chamber_c",)][
        int(rng.integers(0, 3))]
    soak = soak_min if soak_min is not None else float(rng.choice([10.0, 20.0, 45.0]))
    vib_level = float(rng.uniform(0.3e-3, 1.5e-3))
    vib = tuple(vib_level if t < 5.0 else (0.15e-3 if rng.random() < 0.2 else 0.0) for t in sp)
    sched = schedule or str(rng.choice(["dense24", "sparse18", "oblique36"]))
    return Protocol2(
        name=f"{kind}/{sched}/{'+'.join(cols)}/{soak:.0f}min", setpoints_c=sp, soak_min=soak,
        schedule=sched, columns=tuple(cols),
        die_tau_s=20.0 if cols == ("chamber_c",) else float(rng.uniform(300, 900)),
        n_samples=int(rng.choice([20, 50, 100, 200])), vib_sd_g=vib,
        irregular=bool(kind in ("irregular", "sparse") or rng.random() < 0.3),
        power_cycle_at=len(sp) // 2 if kind == "updown" else None,
        sensor_noise_g=float(rng.uniform(40e-6, 120e-6)))
