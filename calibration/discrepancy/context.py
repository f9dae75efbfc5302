"""Per-reading facts every catalogue effect may use (times, temperatures, steps, inputs).

Built once from a :class:`~calibration.recording.Recording`; the effects
read it to form their regressors in *raw-output space* ((N,3,k) arrays in g),
which :mod:`calibration.discrepancy.problem` maps into residual space.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibration import table_pose
from calibration.recording import Recording

AXES = ("x", "y", "z")


@dataclass
class DesignContext:
    """What each effect sees (N readings); ``input_g``: ref, or calibrated f in norm mode."""

    mode: str  # "reference" | "norm"
    t_s: np.ndarray  # (N,)
    temp_c: np.ndarray  # (N,) thermal-model temperature (NaN-free; 0 when none recorded)
    temperature_source: str  # "sensor_c" | "chamber_c" | "none"
    has_chamber_c: bool
    has_sensor_c: bool
    steps: np.ndarray  # (N,) int step index
    positions: np.ndarray  # (N,) int
    step_temp_c: dict[int, float]  # median temperature per step
    direction: np.ndarray  # (N,) +1 heating, −1 cooling, 0 unknown (last excursion)
    time_since_step_s: np.ndarray  # (N,) time since the step's first reading
    input_g: np.ndarray  # (N,3) specific force in the sensor frame (approx.)
    sd_g: np.ndarray | None  # (N,3) within-window sd, when recorded
    draw_dtemp_g_per_c: np.ndarray  # (N,3) ∂raw/∂T of the fitted base model
    session: np.ndarray | None  # (N,) when a session column is present
    # Reference mode: ``refit_shift(dT) -> (Δraw, ∂raw/∂T at T + dT)``, both (N,3) g, of the
    # base model refitted with its temperature moved by dT (see problem.py); None in norm mode.
    refit_shift: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None
    # Norm mode: ``temperature_shift(dT) -> Δraw`` (N,3) g, the fitted base's raw output at
    # T + dT minus at T for the same calibrated output (no refit); None in reference mode.
    temperature_shift: Callable[[np.ndarray], np.ndarray] | None = None
    # (N,) samples averaged per reading (the ``n`` column), when recorded: how noisy each
    # reading's own ``sd_*`` is as an estimate of its window's variance.
    n_samples: np.ndarray | None = None
    # (N,4) unit quaternions of the table's commanded pose per reading (sensor to lab;
    # calibration/table_pose.py), when the recording has the ``pose_q*`` columns.
    pose_q: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.t_s.size

    @property
    def step_ids(self) -> list[int]:
        return sorted(self.step_temp_c)

    @property
    def one_way(self) -> bool:
        """Step temperatures monotonic: every step is reached from the same side."""
        temps = [self.step_temp_c[s] for s in self.step_ids]
        d = np.diff(temps)
        d = d[np.abs(d) > 0.5]
        return d.size == 0 or bool(np.all(d > 0) or np.all(d < 0))


def base_context(rec: Recording, mode: str, input_g: np.ndarray) -> DesignContext:
    """Context without the model derivative (filled in once the base fit exists)."""
    n = len(rec)
    t = rec.t_s.astype(float)
    if rec.has_temperature:
        temp = rec.temperature_c()
        temp = np.where(np.isfinite(temp), temp, np.nanmedian(temp))
        source = rec.temperature_source
    else:
        temp, source = np.zeros(n), "none"
    steps = rec.steps() if rec.has_temperature or rec.has("step") else np.zeros(n, int)
    positions = rec.positions()
    step_temp = {int(s): float(np.median(temp[steps == s])) for s in np.unique(steps)}
    direction = plateau_directions(rec, steps, step_temp)
    since = np.zeros(n)
    for s in step_temp:
        m = steps == s
        since[m] = t[m] - t[m].min()
    sd = None
    if all(rec.has(c) for c in ("sd_x", "sd_y", "sd_z")):
        sd = np.column_stack([rec.columns[c] for c in ("sd_x", "sd_y", "sd_z")])
        sd = np.where(np.isfinite(sd), sd, np.nanmedian(sd, axis=0))
    session = None
    if "session" in rec.columns and rec.has("session"):
        session = np.nan_to_num(rec.columns["session"], nan=0).astype(int)
    n_samples = None
    if rec.has("n"):
        n_samples = np.asarray(rec.columns["n"], float)
        n_samples = np.where(np.isfinite(n_samples) & (n_samples > 1), n_samples, np.nan)
        n_samples = None if np.all(np.isnan(n_samples)) else n_samples
    return DesignContext(
        mode=mode, t_s=t, temp_c=temp, temperature_source=source,
        has_chamber_c=rec.has("chamber_c"), has_sensor_c=rec.has("sensor_c"),
        steps=steps, positions=positions, step_temp_c=step_temp, direction=direction,
        time_since_step_s=since, input_g=np.asarray(input_g, float),
        sd_g=sd, draw_dtemp_g_per_c=np.zeros((n, 3)), session=session, n_samples=n_samples,
        pose_q=table_pose.read_poses(rec) if mode == "reference" else None,
    )


def plateau_directions(rec: Recording, steps: np.ndarray,
                       step_temp: dict[int, float]) -> np.ndarray:
    """Heating (+1) / cooling (−1) / unknown (0) per reading: each plateau's last excursion,
    read from the commanded temperatures where recorded (:func:`_step_targets_c`), else from
    ``step_temp``. The one reading of direction for ``diagnose`` and ``--against``."""
    return _directions(steps, _step_targets_c(rec, steps, step_temp))


def _step_targets_c(rec: Recording, steps: np.ndarray,
                    step_temp: dict[int, float]) -> dict[int, float]:
    """Each plateau's commanded temperature (°C): its median ``setpoint_c`` when every
    plateau has one, else ``step_temp`` (the median recorded temperature).

    Why (issue 22): the heating/cooling direction of a plateau is the chamber's excursion to
    it. With soaks shorter than ~3 die time constants the die is still moving when the
    readings are taken, so plateau medians can fall out of setpoint order: cooled from room
    temperature to −20 °C and still −9 °C there, the die reads −12 °C on the next plateau
    (−11 °C, reached by heating), and medians called both plateaus' directions the wrong way
    round (a hysteresis at twice its detectable size was named ``temperature_rate``).
    """
    if not rec.has("setpoint_c"):
        return step_temp
    sp = np.asarray(rec.columns["setpoint_c"], float)
    out: dict[int, float] = {}
    for s in step_temp:
        v = sp[steps == s]
        v = v[np.isfinite(v)]
        if v.size == 0:
            return step_temp
        out[s] = float(np.median(v))
    return out


def _directions(steps: np.ndarray, step_temp: dict[int, float]) -> np.ndarray:
    """Last-excursion direction per step; the first step is assumed reached from the far side.

    Why: a campaign usually starts at room temperature and goes to an extreme first,
    so the first step is approached opposite to the move that follows it.
    """
    ids = sorted(step_temp)
    d: dict[int, int] = {}
    prev = 0
    for k, s in enumerate(ids):
        if k > 0 and abs(step_temp[s] - step_temp[ids[k - 1]]) > 0.5:
            prev = 1 if step_temp[s] > step_temp[ids[k - 1]] else -1
        d[s] = prev
    if len(ids) > 1:
        first = next((d[s] for s in ids[1:] if d[s] != 0), 0)
        for s in ids:
            if d[s] != 0:
                break
            d[s] = -first
    return np.array([d[int(s)] for s in steps], dtype=float)
