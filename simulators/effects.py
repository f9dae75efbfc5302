"""Truth-model effects: the physics the base model leaves out (``docs/effects.md``).

Each class implements the :class:`simulators.truth.Effect` protocol with the
catalogue id as ``effect_id`` and the compact model of effects.md, with its
physical parameters named with units. Effects act on the **averaged** readings
of :func:`simulators.campaign_sim.simulate_campaign` (one row per reading).

* ``raw_delta_g(ctx, truth, rng)`` -- additive change of the raw output (N,3) g;
* ``temperature_delta_c(ctx, rng)`` -- additive change of the temperature channel (N,) °C.

``thermal_lag`` is not an additive effect: the die follows the chamber air
through the rig's first-order lag ``RigPhysics.die_tau_s``; it shows in a
recording when only ``chamber_c`` is recorded (the model then regresses on
the air, not the die). :class:`ThermalLag` sets both.

Each physical term is computed by the pure function in the effect's diagnosis
module (``calibration/discrepancy/effects/<id>.py``, docs/diagnosis.md §4): one
place per effect's physics. What stays here is the twin's own part: random
draws, session power-on times and the mapping from findings; the base-model response
is :meth:`SensorTruth.ideal_raw_g` (``calibration.sfem.inverse``).

How large each effect must be to be seen under a protocol ("minimum
detectable size") is computed by ``benchmarks/blind/detectability.py``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from calibration.discrepancy.effects.bias_drift import drift_offset_g
from calibration.discrepancy.effects.cross_coupling import cross_coupling_g
from calibration.discrepancy.effects.filter_delay import delayed_input_shift_g
from calibration.discrepancy.effects.lever_arm import centripetal_g
from calibration.discrepancy.effects.outlier import spike_mean_fraction
from calibration.discrepancy.effects.scale_nonlinearity import scale_nonlinearity_g
from calibration.discrepancy.effects.self_heating import warmup_delta_c
from calibration.discrepancy.effects.session_offset import session_offset_g
from calibration.discrepancy.effects.temperature_rate import rate_offset_g
from calibration.discrepancy.effects.temperature_sensor import channel_error_c, channel_step_c
from calibration.discrepancy.effects.thermal_hysteresis import hysteresis_offset_g
from calibration.discrepancy.effects.turntable_geometry import SHAPE_LAB_TILT, tilted_ref_g
from calibration.discrepancy.effects.turntable_geometry import lab_to_sensor as lab_to_sensor
from calibration.discrepancy.effects.vibration_rectification import rectified_offset_g
from calibration.gravity import STANDARD_GRAVITY_M_S2
from simulators.truth import Context, SensorTruth

G0_M_S2 = STANDARD_GRAVITY_M_S2


def _axes(p: dict, pattern: str, default: float | None = None) -> np.ndarray:
    """(3,) from a finding's per-axis parameters ``pattern.format(axis)``."""
    keys = [pattern.format(a) for a in ("x", "y", "z")]
    if default is None:
        return np.array([float(p[k]) for k in keys])
    return np.array([float(p.get(k, default) or default) for k in keys])


def _vec3(v: float | Sequence[float] | np.ndarray) -> np.ndarray:
    return np.broadcast_to(np.asarray(v, float), (3,)).copy()


@dataclass
class _RawOnly:
    """Mixin: effects that leave the temperature channel alone."""

    def temperature_delta_c(self, ctx: Context, rng: np.random.Generator) -> np.ndarray:
        return np.zeros(ctx.t_s.size)


# --- thermal ---------------------------------------------------------------
@dataclass
class ThermalLag:
    """``thermal_lag``: the die follows the chamber air with time constant ``tau_s``.

    Not an additive effect: it is rig physics. :meth:`physics` returns the rig
    with ``die_tau_s = tau_s``; :data:`COLUMNS` is the temperature recording
    that exposes it (chamber only: the model regresses on the air). With
    ``sensor_c`` recorded the lag is regressed away (effects.md: "gone when
    regressed on the die temperature").
    """

    tau_s: float
    effect_id: str = "thermal_lag"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> ThermalLag:
        """The twin counterpart of a ``thermal_lag`` finding (rig physics: τ)."""
        return cls(tau_s=float(p["tau_s"]))
    COLUMNS: ClassVar[tuple[str, ...]] = ("chamber_c",)

    def physics(self, base: object) -> object:
        return replace(base, die_tau_s=float(self.tau_s))  # type: ignore[type-var]


@dataclass
class ThermalHysteresis(_RawOnly):
    """``thermal_hysteresis``: ``raw += direction × h_g`` (±h per axis by last excursion).

    ``direction`` is +1 after heating, −1 after cooling, 0 before any excursion.
    """

    h_g: np.ndarray
    effect_id: str = "thermal_hysteresis"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> ThermalHysteresis:
        return cls(h_g=_axes(p, "h_{}_ug") * 1e-6)

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        return hysteresis_offset_g(ctx.direction, self.h_g)


@dataclass
class TemperatureRate(_RawOnly):
    """``temperature_rate``: ``raw += k_g_per_c_per_s × dT_die/dt`` per axis."""

    k_g_per_c_per_s: np.ndarray
    effect_id: str = "temperature_rate"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> TemperatureRate:
        # the finding is per °C/min of the recorded slope; this is per °C/s of the die rate
        return cls(k_g_per_c_per_s=_axes(p, "k_rate_{}_ug_per_c_per_min") * 1e-6 * 60.0)

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        # the twin acts on the die's rate (°C/s); the diagnosis sees the recorded slope
        return rate_offset_g(ctx.die_rate_c_per_s, self.k_g_per_c_per_s)


@dataclass
class SelfHeating:
    """``self_heating``: the die runs ``delta_c`` above the chamber, after a warm-up.

    ``ΔT(t) = delta_c · (1 − exp(−(t − t_on)/warmup_tau_s))`` with ``t_on`` the
    power-on time of the reading's session (``session_on_s[s]``; default 0 for
    session 0 and the first reading of each later session). The output follows
    the warmer die (base model at die + ΔT) and so does the sensor's own
    temperature channel.
    """

    delta_c: float
    warmup_tau_s: float = 0.0
    session_on_s: tuple[float, ...] | None = None
    effect_id: str = "self_heating"

    def _delta_c(self, ctx: Context) -> np.ndarray:
        t_on = np.zeros(ctx.t_s.size)
        for s in np.unique(ctx.session):
            m = ctx.session == s
            if self.session_on_s is not None:
                t_on[m] = self.session_on_s[int(s)]
            elif s != ctx.session[0]:
                t_on[m] = ctx.t_s[m].min()
        # the twin knows each session's power-on time; the warm-up curve is shared
        return warmup_delta_c(ctx.t_s - t_on, self.delta_c, self.warmup_tau_s)

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        dT = self._delta_c(ctx)
        return truth.ideal_raw_g(ctx.ref_g, ctx.die_c + dT) - truth.ideal_raw_g(
            ctx.ref_g, ctx.die_c)

    def temperature_delta_c(self, ctx: Context, rng: np.random.Generator) -> np.ndarray:
        return self._delta_c(ctx)


@dataclass
class TemperatureSensor:
    """``temperature_sensor``: errors of the temperature channel only (output untouched).

    ``T_read += offset_c + k2_per_c · (T_die − 25)²`` plus glitches of
    ``glitch_c`` on ``glitch_rows`` (or each reading with ``glitch_probability``), plus a
    step of ``step_c`` from campaign step ``from_step`` on (a re-zeroed channel).
    """

    offset_c: float = 0.0
    k2_per_c: float = 0.0
    glitch_c: float = 0.0
    glitch_rows: tuple[int, ...] = ()
    glitch_probability: float = 0.0
    step_c: float = 0.0
    from_step: int = 0
    effect_id: str = "temperature_sensor"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> TemperatureSensor:
        """The twin counterpart of a channel-step finding, or of a glitch on ``rows``."""
        if "glitch_c" in p:
            return cls(glitch_c=float(p["glitch_c"]), glitch_rows=tuple(int(r) for r in rows))
        return cls(step_c=float(p["step_c"]), from_step=int(p["from_step"]))

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        return np.zeros((ctx.t_s.size, 3))

    def temperature_delta_c(self, ctx: Context, rng: np.random.Generator) -> np.ndarray:
        d = channel_error_c(ctx.die_c, self.offset_c, self.k2_per_c)
        if self.step_c:
            d = d + channel_step_c(ctx.step, self.from_step, self.step_c)
        g = np.zeros(ctx.t_s.size)
        g[list(self.glitch_rows)] = self.glitch_c
        if self.glitch_probability > 0:
            g[rng.random(ctx.t_s.size) < self.glitch_probability] = self.glitch_c
        return d + g


@dataclass
class VibrationRectification(_RawOnly):
    """``vibration_rectification``: ``raw += c_per_g × σ²_vib`` per axis (σ_vib in g rms).

    σ_vib comes from the rig (``RigPhysics.vib_sd_g`` or ``vib_sd_g_by_step``,
    e.g. the compressor running below 0 °C) and also widens ``sd_*``.
    """

    c_per_g: np.ndarray
    effect_id: str = "vibration_rectification"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> VibrationRectification:
        return cls(c_per_g=_axes(p, "c_{}_per_g"))

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        return rectified_offset_g(ctx.vib_sd_g, self.c_per_g)


# --- input-dependent -------------------------------------------------------
@dataclass
class ScaleNonlinearity(_RawOnly):
    """``scale_nonlinearity``: ``raw_i += K2_i a_i² + K3_i a_i³``, a_i the true input on axis i."""

    k2_per_g: np.ndarray = field(default_factory=lambda: np.zeros(3))
    k3_per_g2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    effect_id: str = "scale_nonlinearity"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> ScaleNonlinearity:
        return cls(k2_per_g=_axes(p, "k2_{}_ug_per_g2") * 1e-6,
                   k3_per_g2=_axes(p, "k3_{}_ug_per_g3") * 1e-6)

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        return scale_nonlinearity_g(ctx.ref_g, self.k2_per_g, self.k3_per_g2)


@dataclass
class CrossCoupling(_RawOnly):
    """``cross_coupling``: products of two axes' inputs, one coefficient per axis pair.

    ``raw_x += k_xy a_x a_y + k_xz a_x a_z``, ``raw_y += k_xy a_x a_y + k_yz a_y a_z``,
    ``raw_z += k_xz a_x a_z + k_yz a_y a_z`` (each pair couples into both its axes).
    """

    k_xy_per_g: float = 0.0
    k_xz_per_g: float = 0.0
    k_yz_per_g: float = 0.0
    effect_id: str = "cross_coupling"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> CrossCoupling:
        return cls(**{f"k_{q}_per_g": float(p[f"k_{q}_ug_per_g2"]) * 1e-6
                      for q in ("xy", "xz", "yz")})

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        k = np.array([self.k_xy_per_g, self.k_xz_per_g, self.k_yz_per_g], float)
        return cross_coupling_g(ctx.ref_g, k)


@dataclass
class LocalGravity(_RawOnly):
    """``local_gravity``: the true |g| is ``g_local`` (in units of the nominal 1 g).

    ``raw delta = A⁻¹ ref (g_local − 1)``: a common scale factor, unobservable in
    any static tumble (absorbed by the scale factors).
    """

    g_local: float
    effect_id: str = "local_gravity"

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        return truth.ideal_raw_g(ctx.ref_g * self.g_local, ctx.die_c) - truth.ideal_raw_g(
            ctx.ref_g, ctx.die_c)


@dataclass
class TurntableGeometry(_RawOnly):
    """``turntable_geometry``: the rig's base is tilted by ``base_tilt_rad`` (about lab x, y).

    Gravity is constant in the lab frame but tilted: the true specific force is
    ``C_pos · R_tilt · up`` instead of ``C_pos · up``, so ``raw delta = A⁻¹ (ref' − ref)``.
    A constant rotation in the *sensor* frame would be misalignment; this one is constant
    in the lab frame. ``C_pos``: the table's pose of each reading where the context has it
    (``Context.lab_to_sensor``: the twin's table holds each reference in the pose the
    engine commands), else, or with ``through_poses`` False, the minimal rotation onto the
    reference (:func:`lab_to_sensor`: the convention a tilt found without recorded poses is
    fitted in, so a twin built from such a finding reproduces what was fitted).
    """

    base_tilt_rad: np.ndarray
    effect_id: str = "turntable_geometry"
    through_poses: bool = True

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> TurntableGeometry:
        """The lab-frame tilt the finding fitted: through the recorded poses (its shape 3),
        else to its pose turns in :func:`lab_to_sensor`'s convention."""
        return cls(base_tilt_rad=np.array([float(p["tilt_x_urad"]),
                                           float(p["tilt_y_urad"])]) * 1e-6,
                   through_poses=p.get("shape") == SHAPE_LAB_TILT)

    def true_ref_g(self, ref_g: np.ndarray, pose_lab_to_sensor: np.ndarray | None = None
                   ) -> np.ndarray:
        pose = pose_lab_to_sensor if self.through_poses else None
        return tilted_ref_g(ref_g, self.base_tilt_rad, pose)

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        true = self.true_ref_g(ctx.ref_g, ctx.lab_to_sensor)
        return truth.ideal_raw_g(true, ctx.die_c) - truth.ideal_raw_g(ctx.ref_g, ctx.die_c)


@dataclass
class LeverArm(_RawOnly):
    """``lever_arm``: the sensor sits ``r_m`` (sensor frame, m) off the rotation axis.

    Centripetal ``ω × (ω × r) / g0`` while rotating (constant rate: no tangential
    term); exactly zero for static readings (``ctx.omega_rad_s is None`` or 0).
    """

    r_m: np.ndarray
    effect_id: str = "lever_arm"

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        N = ctx.t_s.size
        if ctx.omega_rad_s is None:
            return np.zeros((N, 3))
        w = np.asarray(ctx.omega_rad_s, float)
        a = centripetal_g(w, self.r_m)
        return truth.ideal_raw_g(ctx.ref_g + a, ctx.die_c) - truth.ideal_raw_g(
            ctx.ref_g, ctx.die_c)


@dataclass
class FilterDelay(_RawOnly):
    """``filter_delay``: each sample is the input ``delay_s`` earlier than its timestamp.

    Gravity in a frame rotating at ω moves as ``dref/dt = −ω × ref``, so the
    delayed input is ``ref + delay_s · ω × ref`` (tangential, ∝ ω, sign flips
    with direction); zero for static readings.
    """

    delay_s: float
    effect_id: str = "filter_delay"

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        N = ctx.t_s.size
        if ctx.omega_rad_s is None:
            return np.zeros((N, 3))
        d = delayed_input_shift_g(ctx.omega_rad_s, ctx.ref_g, self.delay_s)
        return truth.ideal_raw_g(ctx.ref_g + d, ctx.die_c) - truth.ideal_raw_g(
            ctx.ref_g, ctx.die_c)


# --- time / session --------------------------------------------------------
@dataclass
class BiasDrift(_RawOnly):
    """``bias_drift``: ``raw += rate_g_per_h · t_h + relax_g · (1 − exp(−t/relax_tau_h))``."""

    rate_g_per_h: np.ndarray
    relax_g: np.ndarray = field(default_factory=lambda: np.zeros(3))
    relax_tau_h: float = 10.0
    effect_id: str = "bias_drift"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> BiasDrift:
        return cls(rate_g_per_h=_axes(p, "rate_{}_ug_per_h") * 1e-6)

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        return drift_offset_g(ctx.t_s / 3600.0, self.rate_g_per_h, self.relax_g, self.relax_tau_h)


@dataclass
class SessionOffset(_RawOnly):
    """``session_offset``: ``raw += offsets_g[session]`` (one offset per power session, (S,3))."""

    offsets_g: np.ndarray
    effect_id: str = "session_offset"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> SessionOffset:
        return cls(offsets_g=np.vstack([np.zeros(3), _axes(p, "offset_{}_ug") * 1e-6]))

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        return session_offset_g(ctx.session, self.offsets_g)


@dataclass
class Outlier(_RawOnly):
    """``outlier``: a few readings far off, isolated in time.

    The recorded row is an average of ``n`` samples. With ``spike_samples``
    set, a spike of ``size_g`` on that many samples shifts the mean by
    ``size_g · spike_samples / n``; without it the whole reading is disturbed
    by ``size_g`` (shock, door opened). Rows are ``rows`` or drawn with
    ``probability`` per reading.
    """

    size_g: np.ndarray
    rows: tuple[int, ...] = ()
    probability: float = 0.0
    spike_samples: int | None = None
    effect_id: str = "outlier"

    @classmethod
    def from_finding(cls, p: dict, rows: Sequence[int] = ()) -> Outlier:
        return cls(size_g=_axes(p, "size_{}_ug", 0.0) * 1e-6, rows=tuple(int(r) for r in rows))

    def hit_rows(self, n_rows: int, rng: np.random.Generator) -> np.ndarray:
        hit = np.zeros(n_rows, bool)
        hit[list(self.rows)] = True
        if self.probability > 0:
            hit |= rng.random(n_rows) < self.probability
        return hit

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        N = ctx.t_s.size
        out = np.zeros((N, 3))
        hit = self.hit_rows(N, rng)
        frac = spike_mean_fraction(self.spike_samples, ctx.n_samples)
        out[hit] = _vec3(self.size_g)[None, :] * frac[hit, None]
        return out


EFFECT_CLASSES: dict[str, type] = {
    c.effect_id: c  # type: ignore[attr-defined]
    for c in (ThermalLag, ThermalHysteresis, TemperatureRate, SelfHeating, TemperatureSensor,
              VibrationRectification, ScaleNonlinearity, CrossCoupling, LocalGravity,
              TurntableGeometry, LeverArm, FilterDelay, BiasDrift, SessionOffset, Outlier)
}


def to_truth_effects(findings: Sequence[object]) -> list[object]:
    """Twin counterparts of diagnosis findings (``Finding`` objects or their JSON dicts).

    Each effect class owns its mapping (``from_finding``); findings without a counterpart
    (``parameter_shift``, ``unexplained``, effects not built here) are skipped. A diagnosis
    object may be passed too (its ``findings`` are used).
    """
    items = getattr(findings, "findings", findings)
    out: list[object] = []
    for f in items:  # type: ignore[union-attr]
        eid = f["effect"] if isinstance(f, dict) else f.effect  # type: ignore[attr-defined]
        params = f["parameters"] if isinstance(f, dict) else f.parameters  # type: ignore
        rows = (f.get("rows") or f.get("where", {}).get("rows") or ()) if isinstance(f, dict) \
            else f.rows  # type: ignore[attr-defined]
        cls = EFFECT_CLASSES.get(eid)
        if cls is not None and hasattr(cls, "from_finding"):
            out.append(cls.from_finding(params, rows))
    return out
