"""Offline soak-campaign simulator: the twin's physics without the wire, for tests and benchmarks.

It interprets the campaign's one plan (calibration/campaign_plan.py), verb by
verb -- ``SetChamber`` commands, ``WaitChamber`` ramps the chamber at its rate
limit until its working setpoint arrives, ``ReadChamber`` returns the simulated
status, ``WaitStable`` soaks (a fixed ``soak_min``: the composite soak verb,
expanded here without its stability decision), each scheduled position is a
move, a settle and a capture of N samples --
integrating the air temperature and the die temperature (first-order lag
``tau_s`` behind the air; the plant's steps are ``calibration.thermal_plant``'s), and
writes recording format v1 rows. The wire-level
twin (``simulators/rig.py``) produces the same physics through Modbus and the
serial bridge; this one is for the thousands of campaigns a benchmark needs.

Averaged readings are drawn directly from their sampling distribution (mean of
N samples ~ normal with σ/√N; sd from a χ distribution) -- exact for white
noise and ~200× faster than drawing every sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from calibration import campaign_plan as plan
from calibration.campaign_spec import DEFAULT_SETPOINTS_C, CampaignSpec
from calibration.recording import Recording
from calibration.table_pose import POSE_COLUMNS, pose_quaternion
from calibration.thermal_plant import (
    AMBIENT_C,
    DEFAULT_AIR_TAU_S,
    DEFAULT_RAMP_C_PER_MIN,
    lag_step,
    rate_limited,
)
from drivers.geometry import angles_for_references, rotation_for_angles
from drivers.protocols import ChamberStatus
from simulators.truth import Context, SensorTruth, averaged_readings


@dataclass
class RigPhysics:
    """Chamber and fixture dynamics of the offline campaign."""

    ramp_c_per_min: float = DEFAULT_RAMP_C_PER_MIN  # chamber ramp-rate limit
    air_tau_s: float = DEFAULT_AIR_TAU_S  # air settling behind the working setpoint
    die_tau_s: float = 600.0  # sensor die behind the air (fixture mass, airflow)
    move_s: float = 12.0  # table slew + settle between positions
    pv_noise_c: float = 0.02  # chamber PV noise (rms)
    start_c: float = AMBIENT_C
    dt_s: float = 10.0  # integration step during ramp and soak
    vib_sd_g: float = 0.0  # chamber vibration at the sensor (rms g), see vibration_rectification
    # Per-step vibration (rms g), e.g. the compressor running at cold setpoints; overrides
    # vib_sd_g when given (one entry per setpoint). See compressor_vibration().
    vib_sd_g_by_step: tuple[float, ...] | None = None


def compressor_vibration(
    setpoints_c: Sequence[float], sd_g: float, on_below_c: float = 0.0
) -> tuple[float, ...]:
    """Per-step vibration: ``sd_g`` rms where the compressor runs (setpoint < ``on_below_c``)."""
    return tuple(float(sd_g) if sp < on_below_c else 0.0 for sp in setpoints_c)


@dataclass
class SimCampaign:
    recording: Recording
    die_c: np.ndarray  # true die temperature per row
    air_c: np.ndarray  # true air temperature per row
    truth: SensorTruth
    extra: dict = field(default_factory=dict)


def simulate_campaign(
    truth: SensorTruth,
    setpoints_c: Sequence[float] = DEFAULT_SETPOINTS_C,
    schedule: np.ndarray | None = None,
    soak_min: float = 60.0,
    samples_per_position: int = 200,
    seed: int = 0,
    *,
    physics: RigPhysics | None = None,
    temperature_columns: Sequence[str] = ("chamber_c", "sensor_c"),
    sessions: Sequence[int] | None = None,
    return_truth: bool = False,
    position_order: str = "table",
    position_order_seed: int | None = None,
    record_poses: bool = True,
) -> Recording | SimCampaign:
    """Simulate a soak campaign and return its v1 recording (or a :class:`SimCampaign`).

    ``schedule`` is (n,3) unit gravity vectors in the sensor frame (default the
    seed's Table 1); the same schedule is used at each step. ``sessions`` gives
    a power-session index per step (default: one session). ``position_order`` /
    ``position_order_seed`` are the campaign spec's keys (docs/engine.md, "Position
    order"; default the schedule's order here); the recording's ``visit`` column is
    each row's index within its step in time order. The table holds each reference in the
    pose the engine commands for it (``drivers.geometry.angles_for_reference``), which a
    tilted base turns gravity through; ``record_poses``: the recording also gives those
    poses (``pose_q*``, as the engine writes them).
    """
    from calibration.schedules import table1

    ph = physics or RigPhysics()
    refs = table1() if schedule is None else np.asarray(schedule, float)
    rng = np.random.default_rng(seed)
    n = int(samples_per_position)

    t, air, die, wsp = 0.0, ph.start_c, ph.start_c, ph.start_c
    rows: dict[str, list[float]] = {k: [] for k in (
        "t_s", "step", "setpoint_c", "position", "air", "die", "rate", "dir", "session",
        "ref", "visit")}
    direction = 0
    visits: dict[int, int] = {}  # rows saved so far per step
    last_sp = ph.start_c
    die_before = die

    def advance(dt: float, target: float) -> None:
        nonlocal t, air, die, wsp
        wsp = rate_limited(wsp, target, ph.ramp_c_per_min / 60.0 * dt)
        air = lag_step(air, wsp, dt, ph.air_tau_s)
        die = lag_step(die, air, dt, ph.die_tau_s)  # driven by the air at the step's end
        t += dt

    # The campaign's one plan (calibration/campaign_plan.py), interpreted with this module's
    # physics: the chamber ramps at the rig's rate limit, the soak is a fixed soak_min, a
    # move costs move_s (slew and settle), an acquisition n / odr_hz with its reading at
    # mid-capture.
    def handle(msg: plan.Msg) -> ChamberStatus | None:
        nonlocal direction, last_sp, die_before, visits
        if isinstance(msg, plan.SetChamber):
            sp = msg.setpoint_c
            if sp != last_sp:
                direction = 1 if sp > last_sp else -1
            last_sp = sp
        elif isinstance(msg, plan.WaitChamber):
            while abs(wsp - msg.setpoint_c) > 1e-9:  # ramp: arrived when the WSP is there
                advance(ph.dt_s, msg.setpoint_c)
        elif isinstance(msg, plan.ReadChamber):
            return ChamberStatus(air, last_sp, wsp, ph.ramp_c_per_min, True)
        elif isinstance(msg, plan.WaitStable):
            soak_left = soak_min * 60.0
            while soak_left > 1e-9:
                dt = min(ph.dt_s, soak_left)
                advance(dt, msg.setpoint_c)
                soak_left -= dt
        elif isinstance(msg, plan.Move):
            advance(ph.move_s, last_sp)
        elif isinstance(msg, plan.Settle) and msg.settle_s > 0:
            advance(msg.settle_s, last_sp)
        elif isinstance(msg, plan.Wait) and msg.seconds > 0:
            advance(msg.seconds, last_sp)
        elif isinstance(msg, plan.Acquire):
            capture_s = msg.n_samples / truth.odr_hz
            die_before = die
            advance(capture_s / 2, last_sp)
            rows["t_s"].append(t)
            rows["air"].append(air)
            rows["die"].append(die)
            advance(capture_s / 2, last_sp)
            rows["rate"].append((die - die_before) / capture_s)
        elif isinstance(msg, plan.Save):
            rows["step"].append(msg.step)
            rows["setpoint_c"].append(msg.setpoint_c)
            rows["position"].append(msg.position)
            rows["ref"].append(msg.ref_g)
            rows["visit"].append(visits.get(msg.step, 0))
            visits[msg.step] = visits.get(msg.step, 0) + 1
            rows["dir"].append(direction)
            rows["session"].append(sessions[msg.step] if sessions is not None else 0)
        return None  # Save: stored; Home, Checkpoint, Configure, Fit: nothing to simulate

    # The campaign's one spec, with this twin's protocol given explicitly: its rig's ramp,
    # no settle, and its position order (the schedule's unless asked: the recordings and the
    # benchmarks on them were taken in that order; the engine's default is "travel").
    spec = CampaignSpec(setpoints_c=tuple(float(v) for v in setpoints_c), soak_min=soak_min,
                        samples_per_position=n, settle_s=0.0,
                        ramp_c_per_min=float(ph.ramp_c_per_min), odr_hz=float(truth.odr_hz),
                        position_order=position_order,  # type: ignore[arg-type]
                        position_order_seed=position_order_seed)
    plan.interpret(plan.campaign_plan(spec, refs), handle)

    N = len(rows["t_s"])
    ref = np.asarray(rows["ref"], float).reshape(N, 3)  # each row's own, in visiting order
    die_c = np.asarray(rows["die"])
    air_c = np.asarray(rows["air"])
    poses = table_poses(ref)
    ctx = Context(
        t_s=np.asarray(rows["t_s"]),
        die_c=die_c,
        air_c=air_c,
        die_rate_c_per_s=np.asarray(rows["rate"]),
        ref_g=ref,
        step=np.asarray(rows["step"], int),
        direction=np.asarray(rows["dir"], int),
        session=np.asarray(rows["session"], int),
        n_samples=np.full(N, float(n)),
        vib_sd_g=_vibration(ph, np.asarray(rows["step"], int), N),
        lab_to_sensor=poses,
    )
    rec = readings_to_recording(truth, ctx, rng, temperature_columns, pv_noise_c=ph.pv_noise_c,
                                setpoint_c=np.asarray(rows["setpoint_c"]),
                                position=np.asarray(rows["position"], float))
    extra: dict[str, np.ndarray] = {}
    if position_order != "table":  # the table order's recordings stay exactly as they were
        extra["visit"] = np.asarray(rows["visit"], float)
    if record_poses:  # as the engine records a motorised table's commanded pose
        q = pose_quaternion(poses.transpose(0, 2, 1))
        extra.update({c: q[:, j] for j, c in enumerate(POSE_COLUMNS)})
    if extra:
        rec = Recording.from_columns({**rec.columns, **extra})
    if return_truth:
        return SimCampaign(rec, die_c, air_c, truth, {"context": ctx})
    return rec


def table_poses(ref_g: np.ndarray) -> np.ndarray:
    """(N, 3, 3) Rᵀ of the pose the engine commands for each reference (3 axes, inner 0),
    once per distinct reference (a schedule's few dozen, repeated on every plateau)."""
    refs, inverse = np.unique(np.asarray(ref_g, float), axis=0, return_inverse=True)
    poses = np.array([rotation_for_angles(a).T for a in angles_for_references(refs, 3)])
    return poses[inverse.ravel()]


def _vibration(ph: RigPhysics, step: np.ndarray, n_rows: int) -> np.ndarray:
    if ph.vib_sd_g_by_step is None:
        return np.full(n_rows, ph.vib_sd_g)
    return np.asarray(ph.vib_sd_g_by_step, float)[step]


def simulate_static_run(
    truth: SensorTruth,
    refs: np.ndarray,
    die_c: np.ndarray,
    samples_per_position: int = 200,
    seed: int = 0,
    *,
    t_s: np.ndarray | None = None,
) -> SimCampaign:
    """Readings at steady temperatures (air = die), e.g. a verification run."""
    refs = np.asarray(refs, float)
    N = refs.shape[0]
    die = np.broadcast_to(np.asarray(die_c, float), (N,)).copy()
    rng = np.random.default_rng(seed)
    times = np.arange(N) * 30.0 if t_s is None else np.asarray(t_s, float)
    ctx = Context(
        t_s=times, die_c=die, air_c=die, die_rate_c_per_s=np.zeros(N), ref_g=refs,
        step=np.zeros(N, int), direction=np.zeros(N, int), session=np.zeros(N, int),
        n_samples=np.full(N, float(samples_per_position)), vib_sd_g=np.zeros(N),
    )
    rec = readings_to_recording(truth, ctx, rng, ("chamber_c", "sensor_c"), pv_noise_c=0.02,
                                setpoint_c=np.round(die), position=np.arange(N, dtype=float))
    return SimCampaign(rec, die, die, truth, {"context": ctx})


def readings_to_recording(
    truth: SensorTruth,
    ctx: Context,
    rng: np.random.Generator,
    temperature_columns: Sequence[str],
    *,
    pv_noise_c: float,
    setpoint_c: np.ndarray,
    position: np.ndarray,
) -> Recording:
    """Averaged raw readings + temperatures for each reading of ``ctx``, as a v1 Recording."""
    N = ctx.t_s.size
    n = ctx.n_samples
    mean, sd, sensor_c = averaged_readings(truth, ctx, rng)
    cols: dict[str, np.ndarray] = {
        "t_s": ctx.t_s,
        "step": ctx.step.astype(float),
        "setpoint_c": setpoint_c,
    }
    if "chamber_c" in temperature_columns:
        cols["chamber_c"] = ctx.air_c + rng.normal(0, pv_noise_c, N)
    if "sensor_c" in temperature_columns:
        cols["sensor_c"] = sensor_c
    cols.update({
        "position": position,
        "ref_x": ctx.ref_g[:, 0], "ref_y": ctx.ref_g[:, 1], "ref_z": ctx.ref_g[:, 2],
        "ax": mean[:, 0], "ay": mean[:, 1], "az": mean[:, 2],
        "n": n,
        "sd_x": sd[:, 0], "sd_y": sd[:, 1], "sd_z": sd[:, 2],
    })
    return Recording.from_columns(cols)
