"""The one gate before and after a calibration: what the data identify, and refusals.

Three questions, answered in one place for ``calibrate`` and ``diagnose``:

1. **How many orientations?** Capture directions are clustered within the noise
   (:func:`distinct_orientations`): rows, or the noise scatter of one resting
   orientation, are never counted as positions. A one-orientation warm-up of
   100,000 samples is one orientation.
2. **What do they identify?** (:func:`plan`) The SFEM (Eq. 1) needs, per
   temperature step, 10 distinct orientations in norm mode (Eq. 3: 9 parameters)
   or 4 with reference vectors (Eq. 4: 12 parameters, 3 residuals each); which
   parameters the orientations determine is decided by
   :func:`calibration.schedules.identifiability` on the orientations' mean
   directions (:func:`undetermined_parameters`, also used by :mod:`calibration.fit`).
   Fewer orientations with a temperature channel: a warm-up (:mod:`calibration.warmup`),
   each axis' bias change with temperature, and what 2 or more orientations determine
   absolutely (:mod:`calibration.warmup_absolute`, by the same check), everything else
   held. Neither: refused.
3. **Is the model physical?** (:func:`check_model`, :func:`check_thermal_fit`) A fit
   that did not converge, negative spare degrees of freedom counted on orientations,
   a bias beyond :data:`BIAS_MAX_G`, a scale more than :data:`SCALE_MAX_DEV` from 1,
   angles beyond :data:`ANGLE_MAX_RAD`, or a compensated |g| more than
   :data:`NORM_MAX_DEV_G` off local gravity on the data's own captures is refused
   (:class:`GateRefusal`: one line, why and which data would fix it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from calibration import sfem
from calibration.die_follows_air import die_leads_air
from calibration.errors import CalibrationError

if TYPE_CHECKING:  # thermal imports fit, which imports this module
    from calibration.recording import Recording
    from calibration.thermal import ThermalFit, ThermalModel

# Orientations closer than this are one: no SFEM parameter is determined by a spread of
# a degree or two, and a hand re-placing a box on the same face differs by about that.
MIN_SEPARATION_DEG = 2.0
# ... or closer than this many angular noise sd of a reading (raw samples of a noisy part).
NOISE_SIGMAS = 6.0
# Relative singular value below which the orientations do not determine a parameter
# (good schedules have condition numbers 2-3; six axis directions a little off true give
# ~1e-5 for the α in norm mode: far from determined, full rank to a naive check).
STRUCTURAL_REL_TOL = 1e-3


def free_parameter_count(mode: str) -> int:
    """SFEM parameters a fit frees: all 12 of Eq. 1 with references (Eq. 4); 9 in norm
    mode (Eq. 3: b, S, C; a rotation M leaves |g| unchanged)."""
    return sfem.N_PARAMS if mode == "reference" else 9


def min_orientations(mode: str, spare_dof: int) -> int:
    """Distinct orientations a ``mode`` fit needs for ``spare_dof`` spare degrees of freedom:
    ⌈(free parameters + spare) / residuals per orientation⌉ (3 with references, 1 in norm
    mode). The one place every minimum count below comes from."""
    per = 3 if mode == "reference" else 1
    return -(-(free_parameter_count(mode) + spare_dof) // per)


# An SFEM fit at all: norm mode one spare (a χ² to weigh it: 9 + 1, Eq. 3), reference mode
# none counted on orientations (12 residuals from 4; repeat readings give the spare).
NORM_MIN_ORIENTATIONS = min_orientations("norm", 1)  # 10
REFERENCE_MIN_ORIENTATIONS = min_orientations("reference", 0)  # 4
# A temperature step (or a continuous fit) with a held-out figure: 3 spare degrees of
# freedom (calibration.holdout.MIN_SPARE_DOF), so 12 in norm mode and 5 with references.
STEP_SPARE_DOF = 3
# A step calibrates the SFEM when its orientations determine at least bias and scale of
# all three axes (six axis directions: norm mode, α held); fewer is a warm-up. Counting
# any six was not enough: ±z, ±x with references determine eight (bx by bz sx sz azx mx
# my) but not sy, and the per-step fit of all 12 did not converge on such a warm-up.
SFEM_MIN_FITTED = 6
SFEM_REQUIRED = ("bx", "by", "bz", "sx", "sy", "sz")
# Physical sense. No MEMS accelerometer's zero-g offset comes near half a g (ADXL355:
# ±25 mg; consumer parts ±150 mg); sensitivities are within a few percent of nominal;
# axes within a degree or two of orthogonal and of the package.
BIAS_MAX_G = 0.5
SCALE_MAX_DEV = 0.25
ANGLE_MAX_RAD = 0.35
# No MEMS accelerometer's zero-g offset drifts faster than a few mg/°C (ADXL355
# ±0.15 mg/°C, consumer parts ±0.2 … 1.5 mg/°C in their datasheets). A fitted slope
# above this is something else that changed with the temperature: a board tilting as it
# warms (1 mrad reads 1 mg), a channel that is not the sensor's.
BIAS_TEMPCO_MAX_G_PER_C = 5e-3
# A slope is judged beyond that limit only when it exceeds it by more than this many of
# its standard errors (where the fit gives its covariance): the derivative of a cubic at
# a warm-up's cold end is set by the few captures at the start of a heating.
BIAS_TEMPCO_SIGMAS = 2.0
# dT/dt (°C/min) the refusal reports is read over this window when the model has no rate
# term of its own (calibration.temperature_conditioning.RATE_WINDOWS_S).
TEMPCO_RATE_WINDOW_S = 40.0
# A still accelerometer on the Earth's surface reads local gravity, 0.9973 g at the
# equator to 1.0026 g at the poles (a part's bias and scale error add a few %): a median
# |a| outside this span is no calibration's concern but a unit or a sensitivity read wrong
# (mg as g, counts with another range's sensitivity), and every model fitted to it is
# wrong (Eq. 1 holds the scale near 1; a warm-up holds it at 1).
PLAUSIBLE_MEDIAN_G: tuple[float, float] = (0.5, 2.0)
# A median |a| within this of 1 g after a power-of-two factor names a range mix-up.
RANGE_SCALE_TOLERANCE_G = 0.05
# g per unit of the acceleration units a log may be written in (the importers' names).
STANDARD_GRAVITY_M_S2 = 9.80665  # m/s² per g (CGPM 1901), converts m/s² files to g
G_PER_UNIT: dict[str, float] = {"g": 1.0, "mg": 1e-3, "m/s2": 1.0 / STANDARD_GRAVITY_M_S2}
UNIT_SHOWN = {"g": "g", "mg": "mg", "m/s2": "m/s²"}
# |compensated| − g on the captures the model was fitted to: a calibrated sensor is
# within a few mg; 50 mg off on its own data is not a calibration.
NORM_MAX_DEV_G = 0.05
# A thermal polynomial that leaves a step more than this (Eq. 9, RMS) while the step's own
# SFEM fit leaves POLY_MAX_RATIO times less follows no temperature law: a MEMS part's
# parameters after a cubic in temperature are within tens of µg (hysteresis, session
# offsets: docs/effects.md), not a milli-g.
POLY_MAX_G = 1e-3
POLY_MAX_RATIO = 20.0
# The fix a refusal names when there are too few orientations.
MORE_ORIENTATIONS = (
    f"record at least {NORM_MIN_ORIENTATIONS} distinct orientations per temperature step "
    f"(or {REFERENCE_MIN_ORIENTATIONS} with reference vectors ref_x/ref_y/ref_z)"
)

# Every raw row left out as taken while the sensor moved (calibration.captures): a flight,
# a vehicle, a hand; what a still accelerometer scatters is
# calibration.importers.STILL_NOISE_CEILING_G.
NO_STILL_READING = (
    "no still reading: every row was left out as taken while the sensor moved or vibrated "
    "(its 1-s scatter is above what a still accelerometer shows, or many times the log's "
    "quietest); nothing can be calibrated: record with the sensor held still in each "
    "orientation (a flight log has no still part)")


class GateRefusal(CalibrationError):
    """The data cannot give a calibration that is not wrong; the message says what would."""


def gravity_problem(median_g: float, unit: str = "g",
                    counts_per_g: float | None = None) -> str | None:
    """Why readings whose median |a| is ``median_g`` (in g, as read with ``unit``) are not a
    still accelerometer's, or None when it is about 1 g (:data:`PLAUSIBLE_MEDIAN_G`).

    The one judgement of |a| against gravity, for every reader (``soakcal import``'s
    declared units, :func:`plan` on a recording's g). The reason names what the numbers
    look like relative to the unit they were read with: for ``counts``, the counts per g
    that would give 1 g (and a power of two of the given sensitivity: another full-scale
    range's); otherwise the unit the file's numbers read as about 1 g in (m/s² given as g
    or mg, mg as g), or a power of two (a firmware dividing by another range's
    sensitivity prints a quarter or a half of the acceleration)."""
    lo, hi = PLAUSIBLE_MEDIAN_G
    if not math.isfinite(median_g) or lo <= median_g <= hi:
        return None
    head = f"median |a| is {median_g:.4g} g, not about 1 g"
    if unit == "counts" and counts_per_g:
        counts = median_g * counts_per_g
        k = _power_of_two(median_g)
        rng = (f"; ×{2.0 ** k:g} it is {median_g * 2.0 ** k:.4g} g: the sensitivity of "
               f"another full-scale range? (--counts-per-g {counts_per_g / 2.0 ** k:g})"
               if k else "")
        return (f"{head}: the counts read about {counts:.4g} per g, not the "
                f"{counts_per_g:g} given{rng}")
    numbers = median_g / G_PER_UNIT.get(unit, 1.0)
    for name, per in G_PER_UNIT.items():
        if name != unit and lo <= numbers * per <= hi:
            read = UNIT_SHOWN.get(unit, unit)
            return f"{head}; it looks like {UNIT_SHOWN[name]} (read as {read})"
    k = _power_of_two(median_g)
    if k:
        how = f" (as --accel-unit counts: --counts-per-g {2.0 ** -k:g})" if unit in (
            "g", "counts") else ""
        return (f"{head}; ×{2.0 ** k:g} it is {median_g * 2.0 ** k:.4g} g: read with the "
                f"sensitivity of another full-scale range?{how}")
    return head


def check_gravity(raw_g: np.ndarray, outcome: str = "no model written") -> None:
    """Refuse readings in g whose median |a| is not about 1 g (:func:`gravity_problem`):
    a recording's ax, ay, az in another unit, or read with another range's sensitivity.
    ``calibrate`` (through :func:`plan`), ``diagnose`` and ``compensate`` ask it."""
    raw = np.atleast_2d(np.asarray(raw_g, float))
    norm = np.linalg.norm(raw, axis=1)
    norm = norm[np.isfinite(norm)]
    problem = gravity_problem(float(np.median(norm))) if norm.size else None
    if problem:
        raise GateRefusal(
            f"{problem}: a still accelerometer reads local gravity, and the recording's "
            f"ax, ay, az are in g (docs/recording.md); {outcome}: convert them "
            f"(soakcal import --format csv --accel-unit …)")


def _power_of_two(median_g: float) -> int:
    """k (±1…4) with median_g × 2^k within :data:`RANGE_SCALE_TOLERANCE_G` of 1 g, else 0."""
    if median_g <= 0.0:
        return 0
    k = int(round(-np.log2(median_g)))
    if k == 0 or abs(k) > 4 or abs(median_g * 2.0**k - 1.0) > RANGE_SCALE_TOLERANCE_G:
        return 0
    return k


@dataclass
class Orientations:
    """Readings grouped into distinct orientations."""

    labels: np.ndarray  # (N,) orientation index of each reading
    directions: np.ndarray  # (K, 3) unit mean direction of each orientation
    counts: np.ndarray  # (K,) readings per orientation
    threshold_deg: float

    @property
    def count(self) -> int:
        return int(self.directions.shape[0])

    def names(self, limit: int = 4) -> str:
        """The first ``limit`` orientations' names (:func:`direction_names`: 'z up',
        'x down', a direction vector, or a face with its tilt where the face repeats)."""
        shown = direction_names(self.directions)[:limit]
        more = self.count - len(shown)
        return ", ".join(shown) + (f" and {more} more" if more > 0 else "")

    def name(self, o: int) -> str:
        """Orientation ``o``'s name, told apart from the others' (:func:`direction_names`)."""
        return direction_names(self.directions)[o]


# A direction within this angle of an axis is named by that axis ('z up').
AXIS_NAME_TOL_DEG = 10.0


def direction_name(u: np.ndarray) -> str:
    """The axis pointing up (gravity's reaction reads +1 g on it) within
    :data:`AXIS_NAME_TOL_DEG`, else the vector."""
    k = int(np.argmax(np.abs(u)))
    if abs(u[k]) >= math.cos(math.radians(AXIS_NAME_TOL_DEG)):
        return f"{'xyz'[k]} {'up' if u[k] > 0 else 'down'}"
    return "(" + ", ".join(f"{v:+.2f}" for v in u) + ")"


def tilted_name(u: np.ndarray) -> str:
    """The nearest axis face and the direction's tilt from it toward each other axis, in
    degrees: 'z down tilted x +3.1° y -2.0°' (tilt toward x = atan(u_x / |u_z|), as an
    inclinometer's two angles). Distinct orientations are at least
    :data:`MIN_SEPARATION_DEG` apart, so at least one of the two angles differs by more
    than a degree: the names tell them apart at 0.1°."""
    k = int(np.argmax(np.abs(u)))
    face = f"{'xyz'[k]} {'up' if u[k] > 0 else 'down'}"
    tilts = []
    for j in (j for j in range(3) if j != k):
        deg = math.degrees(math.atan2(float(u[j]), abs(float(u[k]))))
        tilts.append(f"{'xyz'[j]} {round(deg, 1) + 0.0:+.1f}°")  # + 0.0: never "-0.0°"
    return f"{face} tilted {' '.join(tilts)}"


def direction_names(directions: np.ndarray) -> list[str]:
    """One name per direction, told apart: the simple :func:`direction_name` where it is
    unique, the face and its tilt (:func:`tilted_name`) where two or more directions would
    share it (orientations distinct at 2° but all within 10° of one face)."""
    dirs = np.atleast_2d(np.asarray(directions, float))
    simple = [direction_name(d) for d in dirs]
    seen: dict[str, int] = {}
    for n in simple:
        seen[n] = seen.get(n, 0) + 1
    return [tilted_name(d) if seen[n] > 1 else n for d, n in zip(dirs, simple, strict=True)]


def distinct_orientations(raw_g: np.ndarray, sigma_g: np.ndarray | None = None) -> Orientations:
    """Cluster reading directions into orientations within the noise.

    Two readings are the same orientation when their directions are closer than
    max(:data:`MIN_SEPARATION_DEG`, :data:`NOISE_SIGMAS` × the readings' median angular
    noise |σ|/|a|). Leader clustering in time order (the first unlabelled reading
    leads an orientation and takes every unlabelled reading within the threshold),
    then each orientation's direction is the mean of its readings.
    """
    raw = np.atleast_2d(np.asarray(raw_g, float))
    norm = np.linalg.norm(raw, axis=1)
    u = raw / np.where(norm > 0, norm, 1.0)[:, None]
    thr = math.radians(MIN_SEPARATION_DEG)
    if sigma_g is not None:
        sig = np.broadcast_to(np.asarray(sigma_g, float), raw.shape)
        ang = np.linalg.norm(sig, axis=1) / np.where(norm > 0, norm, 1.0)
        ang = ang[np.isfinite(ang)]
        if ang.size:
            thr = max(thr, NOISE_SIGMAS * float(np.median(ang)))
    cos_thr = math.cos(thr)
    labels = np.full(raw.shape[0], -1)
    # Schedules of distinct positions (the common case) are settled by one tree query: no
    # reading with another within the threshold means each is its own orientation (the
    # leader loop below costs one pass per orientation: 1296 of them in a sphere).
    chord = 2.0 * math.sin(0.5 * thr)  # the threshold angle as a distance between unit vectors
    if 1 < raw.shape[0] <= 20_000 and np.all(np.isinf(
            cKDTree(u).query(u, k=2, distance_upper_bound=chord)[0][:, 1])):
        return Orientations(np.arange(raw.shape[0]), u.copy(), np.ones(raw.shape[0], int),
                            math.degrees(thr))
    # Leader clustering in time order: the first unlabelled reading leads a new
    # orientation and takes every unlabelled reading within the threshold of it.
    centres: list[np.ndarray] = []
    todo = np.arange(raw.shape[0])
    while todo.size:
        lead = u[todo[0]]
        near = u[todo] @ lead >= cos_thr
        labels[todo[near]] = len(centres)
        centres.append(lead)
        todo = todo[~near]
    K = len(centres)
    sums = np.zeros((K, 3))
    np.add.at(sums, labels, u)
    counts = np.bincount(labels, minlength=K)
    dirs = sums / np.linalg.norm(sums, axis=1, keepdims=True)
    return Orientations(labels, dirs, counts, math.degrees(thr))


def undetermined_parameters(directions_g: np.ndarray, mode: str,
                            sigma_g: np.ndarray | None = None) -> tuple[str, ...]:
    """SFEM parameters the distinct orientations of ``directions_g`` cannot determine.

    The identifiability check (:func:`calibration.schedules.identifiability`, relative
    singular value :data:`STRUCTURAL_REL_TOL`) on the orientations' mean directions, not
    on the readings: the noise scatter of one orientation's readings is not a spread of
    directions.
    """
    return _undetermined(distinct_orientations(directions_g, sigma_g), directions_g, mode)


def _undetermined(ori: Orientations, directions_g: np.ndarray, mode: str) -> tuple[str, ...]:
    from calibration.schedules import identifiability  # schedules imports sfem only

    g = float(np.median(np.linalg.norm(directions_g, axis=1)))
    check = identifiability(ori.directions * g, mode, rel_tol=STRUCTURAL_REL_TOL,
                            component_tol=0.1)
    return check.undetermined


@dataclass
class Capacity:
    """What one set of readings can give an SFEM fit, counted on orientations."""

    orientations: Orientations
    mode: str
    fitted: tuple[str, ...]  # parameters the orientations determine
    readings: int

    @property
    def spare(self) -> int:
        """Residuals per orientation (3 reference, 1 norm) × orientations − fitted."""
        return (3 if self.mode == "reference" else 1) * self.orientations.count - len(
            self.fitted)

    def refusal(self) -> str | None:
        """Why an SFEM fit of these readings would not be a calibration, or None."""
        k, p = self.orientations.count, len(self.fitted)
        names = self.orientations.names()
        if p == 0:
            return (f"the {k} distinct orientation(s) ({names}) determine no SFEM "
                    f"parameter in {self.mode} mode")
        if self.mode == "reference" and k < REFERENCE_MIN_ORIENTATIONS:
            # the reference fit moves all 12 parameters: 3 residuals per orientation
            return (f"a reference-mode fit needs at least {REFERENCE_MIN_ORIENTATIONS} "
                    f"distinct orientations, got {k} ({names})")
        if self.spare < 0:
            return (f"{k} distinct orientation(s) ({names}) for {p} parameters "
                    f"({self.spare} spare degrees of freedom)")
        per = 3 if self.mode == "reference" else 1
        if per * self.readings <= p:
            return (f"a {self.mode}-mode fit of {p} parameters needs more than {p} "
                    f"residuals, got {per * self.readings} from {self.readings} reading(s)")
        return None


def capacity(raw_g: np.ndarray, mode: str, sigma_g: np.ndarray | None = None) -> Capacity:
    """Distinct orientations of the readings and the SFEM parameters they determine."""
    ori = distinct_orientations(raw_g, sigma_g)
    free = sfem.PARAM_NAMES if mode == "reference" else sfem.PARAM_NAMES[:9]
    unseen = set(_undetermined(ori, raw_g, mode))
    return Capacity(ori, mode, tuple(n for n in free if n not in unseen),
                    int(np.atleast_2d(raw_g).shape[0]))


@dataclass
class Plan:
    """What ``calibrate`` will fit: the SFEM per step, or a warm-up's bias change."""

    kind: str  # "sfem" | "continuous" | "warmup"
    mode: str  # "reference" | "norm" | "warmup"
    orientations: Orientations
    reason: str  # one line: why this kind
    notes: list[str] = field(default_factory=list)


def plan(captures: Recording, *, continuous: bool = False,
         orientations: Orientations | None = None, source: Recording | None = None) -> Plan:
    """Decide from the capture means what the data identify (module docstring, 2.).

    ``continuous``: the recording has rows on no temperature plateau
    (:func:`calibration.plateaus.segment_recording`); its orientations are then counted
    over the whole recording, for the SFEM in each reading's own temperature
    (:mod:`calibration.continuous`), never per invented step. ``orientations``: the
    captures' :func:`distinct_orientations`, when the caller has them. ``source``: the
    recording the captures were read from (its ``sd_*`` name a unit mistake when no row
    was kept as still, :func:`_sd_unit_hint`). Raises
    :class:`GateRefusal` when nothing can be calibrated.
    """
    if len(captures) == 0:
        # capture_means leaves out only rows taken while the sensor moved: none was still
        raise GateRefusal(_sd_unit_hint(source) or NO_STILL_READING)
    raw = captures.raw_g
    check_gravity(raw)
    ori = orientations or distinct_orientations(raw, captures.sigma_g)
    mode = "reference" if captures.has_reference else "norm"
    summary = (f"{ori.count} distinct orientation(s) ({ori.names()}) in {len(captures)} "
               f"reading(s)")
    if continuous and captures.has_temperature:
        from calibration.plateaus import MIN_POSITIONS_NORM, MIN_POSITIONS_REFERENCE

        need = MIN_POSITIONS_REFERENCE if mode == "reference" else MIN_POSITIONS_NORM
        whole = capacity(raw, mode, captures.sigma_g)
        if (ori.count >= need and whole.refusal() is None
                and _determines_sfem(whole)):
            return Plan("continuous", mode, ori,
                        f"{summary} on no temperature plateau: the SFEM fitted in each "
                        f"reading's own die temperature")
    per_step = _capacity_per_step(captures, mode)
    enough = [s for s, c in per_step.items()
              if c.refusal() is None and _determines_sfem(c)]
    if enough:
        return Plan("sfem", mode, ori, f"{summary}; {len(enough)} of {len(per_step)} step(s) "
                    f"determine bias and scale of every axis")
    if captures.has_temperature:
        most = max((c.orientations.count for c in per_step.values()), default=ori.count)
        held = ("scale, non-orthogonality and misalignment held" if ori.count < 2 else
                "and what the orientations determine absolutely; otherwise scale, "
                "non-orthogonality and misalignment held")
        return Plan("warmup", "warmup", ori,
                    f"{summary}, at most {most} per temperature step: too few for an SFEM "
                    f"fit of bias and scale; calibrated as a warm-up (each axis' bias change "
                    f"with temperature; {held})")
    raise GateRefusal(
        f"{summary} and no temperature: nothing can be calibrated; {MORE_ORIENTATIONS}, "
        f"or record a temperature (sensor_c) while the sensor warms up")


def _determines_sfem(c: Capacity) -> bool:
    """Bias and scale of every axis determined (:data:`SFEM_REQUIRED`), with no refusal."""
    return c.refusal() is None and set(SFEM_REQUIRED) <= set(c.fitted)


def _capacity_per_step(captures: Recording, mode: str) -> dict[int, Capacity]:
    steps = captures.steps() if captures.has_temperature else np.zeros(len(captures), int)
    sig = captures.sigma_g
    return {int(s): capacity(captures.raw_g[steps == s], mode,
                             None if sig is None else sig[steps == s])
            for s in np.unique(steps[steps >= 0])}


# --- after the fit --------------------------------------------------------------
def check_thermal_fit(fit: ThermalFit, captures: Recording) -> None:
    """Refuse an SFEM thermal fit that did not converge or has no spare degrees of freedom.

    Spare degrees of freedom per step are counted on orientations: residuals
    (3 per orientation in reference mode, 1 in norm mode) less the fitted parameters.
    """
    joint = fit.report.get("joint_fit")
    if joint and not joint.get("success", True):
        raise GateRefusal(
            f"the joint thermal fit did not converge ({joint.get('message')}); no model "
            f"written: record more orientations per step, or use --method per_step")
    sig = captures.sigma_g
    for st in fit.steps:
        if not st.fit.success:
            raise GateRefusal(
                f"the SFEM fit of step {st.step} did not converge ({st.fit.message}); "
                f"no model written: {MORE_ORIENTATIONS}")
        idx = fit.row_step == st.step
        cap = capacity(captures.raw_g[idx], fit.model.mode, None if sig is None else sig[idx])
        fitted = int(np.sum(st.fit.identifiable))
        spare = (3 if fit.model.mode == "reference" else 1) * cap.orientations.count - fitted
        if spare < 0:
            raise GateRefusal(
                f"step {st.step} has {cap.orientations.count} distinct orientation(s) for "
                f"{fitted} fitted parameters ({spare} spare degrees of freedom); no model "
                f"written: {MORE_ORIENTATIONS}")
    _check_step_jumps(fit)
    check_model(fit.model, captures, fit.row_temperature_c)


def _check_step_jumps(fit: ThermalFit) -> None:
    """Refuse a thermal polynomial (Eq. 8) that leaves a step more than
    :data:`POLY_MAX_G` (RMS, Eq. 9) while each step's own SFEM fit leaves
    :data:`POLY_MAX_RATIO` times less: the parameters jump between steps (one step's
    readings from another sensor, a re-mount), which no smooth temperature law follows;
    the model would be off by the jump at every temperature. The step named is the one
    whose per-step biases sit furthest from a straight line through the other steps'."""
    steps = [st for st in fit.steps if np.isfinite(st.rmse_polynomial_ug)
             and np.isfinite(st.temperature_c)]
    if len(steps) < 3:
        return
    worst = max(steps, key=lambda st: st.rmse_polynomial_ug)
    meas = max(st.rmse_measurement_ug for st in steps)
    if worst.rmse_polynomial_ug <= max(POLY_MAX_G * 1e6, POLY_MAX_RATIO * meas):
        return
    T = np.array([st.temperature_c for st in steps])
    b = np.array([st.fit.params.to_vector()[sfem.BIAS] for st in steps])
    deg = 1  # a straight line: a cubic through the others swings at the ends
    off = np.zeros_like(b)
    for i in range(len(steps)):
        rest = np.arange(len(steps)) != i
        for k in range(3):
            c = np.polyfit(T[rest], b[rest, k], deg)
            off[i, k] = b[i, k] - np.polyval(c, T[i])
    i, k = np.unravel_index(int(np.argmax(np.abs(off))), off.shape)
    odd = steps[int(i)]
    raise GateRefusal(
        f"the temperature polynomial leaves step {worst.step} "
        f"{worst.rmse_polynomial_ug / 1e3:.2f} mg off (RMS) while each step's own fit leaves "
        f"at most {meas / 1e3:.3f} mg: the sensor's parameters jump between steps (step "
        f"{odd.step}'s bias {sfem.PARAM_NAMES[int(k)]} is {off[i, k] * 1e3:+.2f} mg off the "
        f"other steps' trend), which no temperature law follows: one step's readings from "
        f"another sensor or another mounting?; no model written: re-record that step, or "
        f"calibrate the steps of one sensor and mounting only")


def check_model(model: ThermalModel, captures: Recording,
                temperature_c: np.ndarray | None = None) -> None:
    """Refuse a model outside physical sense (module docstring, 3.).

    The parameters are checked at the ends and the centre of the valid range; the
    compensated |g| on the captures (at ``temperature_c``, each capture's own) for a
    model that claims to give |g| (not a warm-up's bias change).
    """
    temps = [model.t_centre_c]
    if model.valid_c is not None:
        temps += list(model.valid_c)
    names = sfem.PARAM_NAMES
    for T in temps:
        p = model.params_vector_at(T, extrapolate=True)
        at = f" at {T:.1f} °C" if model.temperature_dependent else ""
        k = int(np.argmax(np.abs(p[sfem.BIAS])))
        if abs(p[k]) > BIAS_MAX_G:
            raise GateRefusal(
                f"the fitted bias {names[k]} = {p[k]:+.3g} g{at} is not physical (no "
                f"accelerometer is {BIAS_MAX_G:g} g off); no model written: "
                f"{_fix(model)}")
        s = p[sfem.SCALE]
        k = int(np.argmax(np.abs(s - 1.0)))
        if abs(s[k] - 1.0) > SCALE_MAX_DEV:
            raise GateRefusal(
                f"the fitted scale {names[3 + k]} = {s[k]:.4g}{at} is not physical (more "
                f"than {SCALE_MAX_DEV:.0%} from 1); no model written: {_fix(model)}")
        a = p[6:]
        k = int(np.argmax(np.abs(a)))
        if abs(a[k]) > ANGLE_MAX_RAD:
            raise GateRefusal(
                f"the fitted angle {names[6 + k]} = {a[k]:+.3g} rad{at} is not physical; "
                f"no model written: {_fix(model)}")
    _check_bias_tempco(model, captures, temperature_c)
    if model.mode == "warmup" or temperature_c is None:
        return
    used = np.isfinite(temperature_c) | (not model.temperature_dependent)
    if not used.any():
        return
    cal = model.compensate(captures.raw_g[used],
                           np.nan_to_num(temperature_c[used], nan=model.t_centre_c),
                           extrapolate=True)
    dev = np.abs(np.linalg.norm(cal, axis=1) - model.g_local)
    i = int(np.argmax(dev))
    if dev[i] > NORM_MAX_DEV_G:
        row = int(np.flatnonzero(used)[i])
        raw_norm = float(np.linalg.norm(captures.raw_g[row]))
        raise GateRefusal(
            f"the model gives |g| = {float(np.linalg.norm(cal[i])):.4f} g "
            f"(local gravity {model.g_local:.4f} g) on its own reading {row + 1} "
            f"(t = {float(captures.t_s[row]):.1f} s, |raw| {raw_norm:.4f} g); a calibration "
            f"is within a few mg; no model written: {_fix(model)}")


def check_warmup_residuals(residual_g: np.ndarray, orientations: Orientations,
                           names: tuple[str, ...]) -> None:
    """Refuse a warm-up's absolute fit (:mod:`calibration.warmup_absolute`) whose residuals
    (|f| − g, or f − ref) at one orientation are more than :data:`NORM_MAX_DEV_G` RMS after
    fitting every parameter that orientation moves: no sensor is that far off."""
    r = np.asarray(residual_g, float)
    for o in range(orientations.count):
        rms = float(np.sqrt(np.mean(r[orientations.labels == o] ** 2)))
        if rms > NORM_MAX_DEV_G:
            raise GateRefusal(
                f"after fitting {', '.join(names)} the readings at "
                f"{orientations.name(o)} are still {rms * 1e3:.1f} mg "
                f"off (RMS; a calibration is within a few mg): the orientations were not "
                f"held still, or the references or gravity are wrong; no model written: "
                f"keep the board still on each face and check --gravity-g and ref_*")


def _check_bias_tempco(model: ThermalModel, captures: Recording | None = None,
                       temperature_c: np.ndarray | None = None, n_temps: int = 21) -> None:
    """Refuse a bias slope confidently beyond :data:`BIAS_TEMPCO_MAX_G_PER_C`.

    The slope d b/dT of the fitted bias polynomial (Eq. 8) is judged where the data pin
    it: over the span of the temperatures the model was fitted at (``temperature_c``,
    else the captures' own; the valid range without either), not out to the raw rows'
    extremes a capture mean never reached. It is refused only when it is beyond the limit
    by more than :data:`BIAS_TEMPCO_SIGMAS` of its standard error (from the model's
    ``coeff_cov`` where the fit gives it; the point estimate elsewhere). It is the model as
    fitted: a warm-up's rate term k·dT/dt, when fitted, carries a lagging channel's steep
    onset, and its covariance is marginalised out of the slope's.
    """
    if not model.temperature_dependent or model.degree == 0:
        return
    lo, hi = _pinned_span_c(model, captures, temperature_c)
    if hi > lo:
        # The change the model applies across its data, by its point estimate: what is
        # applied to a reading whatever its standard error (a channel that is not this
        # sensor's temperature gives a slope of noise with an error as large).
        change = (model.params_vector_at(hi, extrapolate=True)[sfem.BIAS]
                  - model.params_vector_at(lo, extrapolate=True)[sfem.BIAS])
        k = int(np.argmax(np.abs(change)))
        if abs(change[k]) > BIAS_TEMPCO_MAX_G_PER_C * (hi - lo):
            raise GateRefusal(mean_tempco_refusal(
                sfem.PARAM_NAMES[k], float(change[k]), lo, hi,
                _fastest_rate_c_per_min(model, captures)))
    temps = np.linspace(lo, hi, n_temps)
    slope, se = bias_slope_g_per_c(model, temps)
    se = np.nan_to_num(se)  # no covariance (a soak's, a ramp's): its point estimate judged
    excess = np.abs(slope) - BIAS_TEMPCO_SIGMAS * se
    k, i = np.unravel_index(int(np.argmax(excess)), excess.shape)
    if excess[k, i] <= BIAS_TEMPCO_MAX_G_PER_C:
        return
    raise GateRefusal(tempco_refusal(
        sfem.PARAM_NAMES[k], float(slope[k, i]), float(se[k, i]), float(temps[i]),
        _fastest_rate_c_per_min(model, captures)))


def bias_slope_g_per_c(model: ThermalModel, temperature_c: np.ndarray, *,
                       with_choice: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(3, n) slope of each axis' bias polynomial (Eq. 8) at ``temperature_c``, g/°C, and
    its standard error (NaN where the model carries no covariance of that axis'
    coefficients: a soak's or a ramp's, an axis a warm-up fitted absolutely).

    The error is the fitted curve's own (``coeff_cov``: what the gate judges), or with
    ``with_choice`` the one that carries the choice of the degree as well
    (``coeff_cov_choice``: what the report states)."""
    d = model.degree
    x = model.x_of(np.asarray(temperature_c, float))
    # d/dT Σ_j c_j x^j = Σ_j j c_j x^(j−1) / scale
    D = np.zeros((x.size, d + 1))
    for j in range(1, d + 1):
        D[:, j] = j * x ** (j - 1) / model.t_scale_c
    slope = model.coeffs[sfem.BIAS] @ D.T
    se = np.full_like(slope, np.nan)
    cov = model.coeff_cov_choice if with_choice else model.coeff_cov
    if cov is not None and cov.shape[1:] == (d + 1, d + 1):
        for k in range(3):
            if np.all(np.isfinite(cov[k])):
                var = np.einsum("ti,ij,tj->t", D, cov[k], D)
                se[k] = np.sqrt(np.clip(var, 0.0, None))
    return slope, se


def tempco_refusal(name: str, slope_g_per_c: float, stderr_g_per_c: float,
                   temperature_c: float, rate_c_per_min: float | None) -> str:
    """The refusal's line: the slope, and every cause that fits the data with its fix."""
    return (f"the fitted bias {name} changes by {slope_g_per_c * 1e3:+.2f} ± "
            f"{stderr_g_per_c * 1e3:.2f} mg/°C at {temperature_c:.2f} °C, beyond any MEMS "
            f"accelerometer's offset drift ({BIAS_TEMPCO_MAX_G_PER_C * 1e3:g} mg/°C) by more "
            f"than {BIAS_TEMPCO_SIGMAS:g} standard errors: {_tempco_causes(rate_c_per_min)}")


def mean_tempco_refusal(name: str, change_g: float, lo_c: float, hi_c: float,
                        rate_c_per_min: float | None) -> str:
    """The refusal's line for a bias change beyond any part's drift across the data (the
    point estimate: what the model would apply), and every cause that fits."""
    return (f"the fitted bias {name} changes by {change_g * 1e3:+.3g} mg over the captures' "
            f"{lo_c:.2f} .. {hi_c:.2f} °C ({change_g * 1e3 / (hi_c - lo_c):+.3g} mg/°C on "
            f"average), beyond any MEMS accelerometer's offset drift "
            f"({BIAS_TEMPCO_MAX_G_PER_C * 1e3:g} mg/°C): {_tempco_causes(rate_c_per_min)}")


def _tempco_causes(rate_c_per_min: float | None) -> str:
    """Every cause of a bias slope no part has, each with its fix (one sentence)."""
    rate = (f" (here up to {rate_c_per_min:.1f} °C/min)"
            if rate_c_per_min is not None and np.isfinite(rate_c_per_min) else "")
    return (f"something else changed with the temperature. Causes that fit: a temperature "
            f"channel lagging the die while the temperature changes fast{rate} (fix: heat "
            f"more slowly, or record a rest and a heating, or a heating and a cooling, so "
            f"that a rate term k·dT/dt can take the lag), or the board tilting or settling "
            f"as it warms, 1 mrad reads 1 mg (fix: keep the board still), or a temperature "
            f"channel that is not this sensor's die or is in another unit (fix: check the "
            f"column and unit read as the temperature, soakcal import --columns temp=NAME "
            f"--temp-unit C|F|K); no model written")


def _pinned_span_c(model: ThermalModel, captures: Recording | None,
                   temperature_c: np.ndarray | None) -> tuple[float, float]:
    """The span of the temperatures the model was fitted at (the valid range without)."""
    T = temperature_c
    if T is None and captures is not None and captures.has_temperature:
        T = captures.temperature_c()
    T = np.asarray(T, float)[np.isfinite(np.asarray(T, float))] if T is not None else None
    if T is None or T.size < 2 or np.ptp(T) <= 0:
        return model.valid_c  # type: ignore[return-value]
    return float(np.min(T)), float(np.max(T))


def _fastest_rate_c_per_min(model: ThermalModel, captures: Recording | None) -> float | None:
    """The largest |dT/dt| (°C/min) of the captures' temperatures, read over the model's
    rate window (or :data:`TEMPCO_RATE_WINDOW_S`); None without a temperature."""
    from calibration.temperature_conditioning import temperature_rate_c_per_min

    if captures is None or not captures.has_temperature or len(captures) < 3:
        return None
    T = captures.temperature_c()
    ok = np.isfinite(T)
    if ok.sum() < 3:
        return None
    window = float((model.temperature_rate or {}).get("window_s") or TEMPCO_RATE_WINDOW_S)
    rate = temperature_rate_c_per_min(captures.t_s[ok], T[ok], window)
    return float(np.max(np.abs(rate)))


def _fix(model: ThermalModel) -> str:
    if model.mode == "warmup":
        return "check the temperature channel and record a longer, smoother warm-up"
    # a model outside physical sense comes from too few orientations, or from readings
    # averaged while the sensor was turned (1-s blocks of a hand-turned log)
    return (f"average only what was recorded with the sensor still (rows taken while it "
            f"was turned: `soakcal import` keeps the static intervals), and "
            f"{MORE_ORIENTATIONS}, spread over the sphere")


def cannot_judge(recording: Recording) -> str | None:
    """Why the SFEM's residuals of ``recording`` cannot be judged, or None.

    ``diagnose`` asks this before it runs: what the base model leaves out can only be
    judged where the gate lets an SFEM be fitted. The reason is the line ``calibrate``
    gives (its refusal, or why it calibrates a warm-up instead). Raw rows are read
    as capture means, as ``calibrate`` reads them, and ``calibrate``'s fit is run
    with its checks after the fit (:func:`check_thermal_fit`, :func:`check_model`):
    a model ``calibrate`` refuses (a fit that did not converge, a |g| far off on its
    own readings: rows taken while the sensor moved) has no residuals worth judging,
    and judging them found "effects" of hundreds of mg.
    """
    from calibration.captures import capture_means
    from calibration.fitting import fit  # fitting imports this module
    from calibration.plateaus import segment_recording

    try:
        check_recording(recording)
    except CalibrationError as exc:
        return str(exc)
    captures = capture_means(recording).recording
    ori = distinct_orientations(captures.raw_g, captures.sigma_g)
    try:
        seg = segment_recording(captures, ori.labels)
        decided = plan(captures, orientations=ori, source=recording,
                       continuous=seg.is_continuous)
        if decided.kind != "continuous":  # cannot be judged either way (below)
            fit(recording)  # calibrate's refusal after the fit, if it refuses
    except CalibrationError as exc:
        return str(exc)
    if decided.kind == "continuous":
        declared = [n for n in seg.notes if "are not temperature plateaus" in n
                    or "fitted as continuous rows" in n]
        why = (f" ({declared[0]}; at the readings' stated noise sd/√n, {seg.row_sigma_ug:.3g} "
               f"µg: if these were soaks, one step id given to two temperatures, or n or sd_* "
               f"too small?)" if declared else "")
        return (f"{decided.reason}{why}; the diagnosis judges per-step residuals, so a "
                f"recording without temperature plateaus cannot be judged: `soakcal "
                f"calibrate` fits it continuously and reports its residuals per temperature "
                f"band")
    if decided.kind == "warmup":
        return (f"{decided.reason}; the SFEM cannot be fitted, so what it leaves out cannot "
                f"be judged")
    return None


# --- what a campaign recording says about itself (before the fit) ---------------
# Chamber air follows the setpoint and the die follows the air: across a campaign's span a
# channel downstream rises at most about as much as the one it follows (a die's
# self-heating and a channel's gain add a few %, a chamber's overshoot a little more). It
# may rise much less: short soaks or a fast ramp leave the die behind (a 2-step bench
# campaign: sensor_c 0.22 °C per °C of setpoint), which is physics, not a unit, and the fit
# reads the die's own channel. A downstream slope above CHANNEL_SLOPE_MAX is no physics: a
# unit or a scale (°F: 1.8, a channel ×10). Judged only over TEMPERATURE_SPAN_MIN_C or more.
CHANNEL_SLOPE_MAX = 1.4
TEMPERATURE_SPAN_MIN_C = 10.0
FAHRENHEIT_PER_C = 1.8
# A reading's direction and its reference's agree within the part's misalignment and its
# bias' tilt of the direction (0.5 g at most: BIAS_MAX_G, under 30°; a few mrad and tens
# of mg in practice); beyond this, the reference is not this reading's orientation.
REF_AGREE_MAX_DEG = 25.0


def check_recording(recording: Recording) -> None:
    """Refuse a campaign recording that contradicts itself before anything is fitted.

    The one place of these checks, for ``calibrate`` (:func:`calibration.fitting.fit`) and
    ``diagnose`` (:func:`cannot_judge`: "cannot judge" with the same reason); ``compensate``
    asks :func:`check_temperature_channels`. Each refusal names the column, the rows and
    the fix:

    - averaged readings that repeat an earlier one value for value (:func:`_check_repeats`);
    - temperature channels in different units, or swapped (:func:`check_temperature_channels`);
    - reference vectors that are not the readings' orientation (:func:`_check_references`).
    """
    _check_repeats(recording)
    check_temperature_channels(recording, "no model written")
    _check_references(recording)


def _where(rec: Recording, i: int) -> str:
    """'t = 2503.6 s, step 0, position 5' of row ``i`` (what a person finds it by)."""
    parts = [f"t = {float(rec.t_s[i]):.1f} s"]
    for name in ("step", "position"):
        if rec.has(name) and np.isfinite(rec.columns[name][i]):
            parts.append(f"{name} {int(rec.columns[name][i])}")
    return ", ".join(parts)


def _check_repeats(rec: Recording) -> None:
    """Refuse averaged readings (``n`` > 1 or ``sd_*``) whose ax, ay, az, and ``sd_*`` where
    recorded, repeat an earlier row's value for value: a noisy sensor's samples never give
    the same mean and scatter to the last digit twice, so the rows are a plateau or a block
    written twice, and the fit would count them as independent readings (their weight
    doubled, their noise halved). Single samples of a quantised channel do repeat, and so
    may the means alone of a few quantised samples: not judged."""
    from calibration.captures import is_raw_samples

    if len(rec) < 2 or is_raw_samples(rec):
        return
    n = rec.columns.get("n")
    if not any(rec.has(c) for c in ("sd_x", "sd_y", "sd_z")) and not (
            n is not None and np.any(np.isfinite(n) & (n > 1))):
        return
    # A row written twice repeats its scatter too: the means of a quantised sensor's few
    # samples lie on a grid of LSB/n and do repeat (an ICM-42688's 1-s means of 50 samples
    # at 0.49 mg LSB, 27 s apart, with sd 0.41 and 0.39 mg), their sd_* do not.
    sd = [np.asarray(rec.columns[c], float)[:, None] for c in ("sd_x", "sd_y", "sd_z")
          if rec.has(c)]
    key = np.hstack([rec.raw_g, *sd])
    _, first, inverse, counts = np.unique(key, axis=0, return_index=True,
                                          return_inverse=True, return_counts=True)
    inverse = np.asarray(inverse).reshape(-1)
    repeat = first[inverse] != np.arange(len(rec))
    if not repeat.any():
        return
    i = int(np.flatnonzero(repeat)[0])
    j = int(first[inverse[i]])
    what = "ax, ay, az and sd_*" if sd else "ax, ay, az"
    raise GateRefusal(
        f"the reading at {_where(rec, i)} repeats the one at {_where(rec, j)} in {what} "
        f"value for value ({int(repeat.sum())} row(s) repeat an earlier one): the average of "
        f"a sensor's noisy samples never comes out the same twice, so a plateau or a block "
        f"was written twice; no model written: remove the repeated rows")


def check_temperature_channels(rec: Recording, outcome: str = "no model written") -> None:
    """Refuse temperature columns (``setpoint_c``, ``chamber_c``, ``sensor_c``) of which a
    downstream one rises more than the one it follows can make it: over a span of at least
    :data:`TEMPERATURE_SPAN_MIN_C`, more than :data:`CHANNEL_SLOPE_MAX` °C per °C. A slope
    of 1.8 is one in °F, 10 one ×10. With a setpoint the odd channel is the one off the
    setpoint; without, ``sensor_c`` is named against ``chamber_c``. A channel that rises
    less (a die behind short soaks) is not refused. Then a ``chamber_c`` that moves through
    its plateaus while ``sensor_c`` holds (the two swapped) is refused
    (:func:`calibration.die_follows_air.die_leads_air`)."""
    names = [c for c in ("setpoint_c", "chamber_c", "sensor_c") if rec.has(c)]
    if len(names) < 2:
        return
    base = names[0]
    for other in names[1:]:
        x, y = rec.columns[base], rec.columns[other]
        ok = np.isfinite(x) & np.isfinite(y)
        if ok.sum() < 3 or np.ptp(x[ok]) < TEMPERATURE_SPAN_MIN_C:
            continue
        slope, offset = (float(c) for c in np.polyfit(x[ok], y[ok], 1))
        if slope <= CHANNEL_SLOPE_MAX:
            continue
        unit = (f"{other} looks like °F ({other} ≈ 1.8 × {base} + 32 is °F)"
                if abs(slope / FAHRENHEIT_PER_C - 1.0) < 0.1 else
                f"one of them is in another unit or scale (×{slope:.3g}?)")
        raise GateRefusal(
            f"{other} rises {slope:.3g} °C per °C of {base} ({other} ≈ {slope:.3g} × {base} "
            f"{offset:+.1f} over {base} {float(np.min(x[ok])):.1f} .. "
            f"{float(np.max(x[ok])):.1f}): the temperature columns of one chamber and die "
            f"move together, so {unit}; {outcome}: write every _c column in °C "
            f"(docs/recording.md)")
    led = die_leads_air(rec, outcome)
    if led:
        raise GateRefusal(led)


def _check_references(rec: Recording) -> None:
    """Refuse reference vectors that are not the readings' orientations: more than
    :data:`REF_AGREE_MAX_DEG` (plus any ``ref_tol_deg``) between a reading's direction and
    its ``ref_*``. When most disagree, the axis permutation or sign flip that makes them
    agree is named (ref_* in another frame); when a few do, the first of them (a reference
    typed for another position, or the sensor placed on another face)."""
    ref = rec.ref_g
    if ref is None:
        return
    raw = rec.raw_g
    ok = np.all(np.isfinite(ref), axis=1) & np.all(np.isfinite(raw), axis=1)
    if not ok.any():
        return
    limit = REF_AGREE_MAX_DEG
    if "ref_tol_deg" in rec.header:
        from calibration.recording import optional_number_column

        tol = optional_number_column(rec, "ref_tol_deg", "degrees")
        if tol is not None and np.any(np.isfinite(tol)):
            limit += float(np.nanmax(tol))

    def angles(r: np.ndarray) -> np.ndarray:
        u = raw[ok] / np.linalg.norm(raw[ok], axis=1, keepdims=True)
        v = r[ok] / np.linalg.norm(r[ok], axis=1, keepdims=True)
        return np.degrees(np.arccos(np.clip(np.sum(u * v, axis=1), -1.0, 1.0)))

    ang = angles(ref)
    bad = ang > limit
    if not bad.any():
        return
    # ref_* in another frame: a signed axis permutation under which the readings agree
    # (most of them; all, where only a few disagree as they are: a flipped y on the
    # Ferraris faces disagrees on the two y faces only)
    best = _best_frame(ref, angles, np.median if np.median(ang) > limit else np.max, limit)
    if best is not None:
        mapping, fix = best
        raise GateRefusal(
            f"{int(bad.sum())} of {int(ok.sum())} readings' directions are more than "
            f"{limit:.0f}° from their reference vectors (median {float(np.median(ang)):.0f}°), "
            f"and agree with them as {mapping}: {fix}; no model written: write ref_x, "
            f"ref_y, ref_z in the sensor's axes (docs/recording.md)")
    if np.median(ang) > limit:
        raise GateRefusal(
            f"the readings' directions are {float(np.median(ang)):.0f}° (median) from their "
            f"reference vectors: ref_* are not these readings' orientations (another "
            f"fixture's frame, or another schedule's); no model written: write ref_x, ref_y, "
            f"ref_z in the sensor's axes, or leave them out for a norm-mode fit")
    i = int(np.flatnonzero(ok)[np.flatnonzero(bad)[0]])
    raise GateRefusal(
        f"the reading at {_where(rec, i)} is {float(ang[bad][0]):.0f}° from its reference "
        f"vector ({', '.join(f'{v:+.3g}' for v in ref[i])}), the others within "
        f"{float(np.max(ang[~bad])):.1f}° of theirs ({int(bad.sum())} reading(s) so): a "
        f"reference written for another position, or the sensor placed on another face; no "
        f"model written: correct ref_* (or position) of those rows, or leave them out")


def _best_frame(ref: np.ndarray, angles: Callable[[np.ndarray], np.ndarray],
                stat: Callable[[np.ndarray], object], limit_deg: float
                ) -> tuple[str, str] | None:
    """The signed axis permutation of ``ref`` under which the readings' angles to it have
    ``stat`` (median, or max) within ``limit_deg``, as ('ax ≈ +ref_y, …', what is wrong),
    or None."""
    import itertools

    best: tuple[float, tuple[int, ...], tuple[int, ...]] | None = None
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            if perm == (0, 1, 2) and signs == (1, 1, 1):
                continue
            r = ref[:, list(perm)] * np.asarray(signs, float)
            med = float(stat(angles(r)))  # type: ignore[arg-type]
            if best is None or med < best[0]:
                best = (med, perm, signs)
    if best is None or best[0] > limit_deg:
        return None
    _, perm, signs = best
    mapping = ", ".join(f"a{'xyz'[i]} ≈ {'+' if s > 0 else '−'}ref_{'xyz'[j]}"
                        for i, (j, s) in enumerate(zip(perm, signs, strict=True)))
    wrong = []
    swapped = [i for i in range(3) if perm[i] != i]
    if swapped:
        wrong.append(" and ".join(f"ref_{'xyz'[i]}" for i in swapped) + " are swapped")
    flipped = [perm[i] for i in range(3) if signs[i] < 0]
    if flipped:
        wrong.append(" and ".join(f"ref_{'xyz'[j]}" for j in flipped) + " have their sign "
                     "flipped" if len(flipped) > 1 else f"ref_{'xyz'[flipped[0]]} has its "
                     "sign flipped")
    return mapping, "; ".join(wrong)


def _sd_unit_hint(source: Recording | None) -> str | None:
    """The refusal for averaged rows all left out as moving whose ``sd_*`` are a still
    accelerometer's scatter ÷ 1000 (written in mg, read in g), or None. Only for a
    campaign's placements (a ``position`` column): a flight's block means also scatter
    tens of mg, for real."""
    from calibration.importers import STILL_NOISE_CEILING_G  # importers read recordings

    if source is None or not source.has("position") or not all(
            source.has(c) for c in ("sd_x", "sd_y", "sd_z")):
        return None
    sd = np.column_stack([source.columns[c] for c in ("sd_x", "sd_y", "sd_z")])
    med = float(np.nanmedian(np.nanmax(sd, axis=1)))
    if not (med > STILL_NOISE_CEILING_G and med * 1e-3 <= STILL_NOISE_CEILING_G):
        return None
    return (f"no still reading: the rows' sd_* (median {med:.4g} g) are more than any still "
            f"accelerometer scatters ({STILL_NOISE_CEILING_G * 1e3:g} mg), so every row was "
            f"left out as taken while the sensor moved; ÷1000 they are {med:.4g} mg, a still "
            f"sensor's noise: sd_* written in mg? sd_* are in g (docs/recording.md); no model "
            f"written: convert sd_x, sd_y, sd_z to g")
