"""Catalogue effects for gen3 (issue 22), written from the public catalogue's physics only
(``docs/effects.md``: the signature and compact model of each id), not from the
diagnosis' modules, the twin or the other generators.

Each effect has a *pattern*: what it adds to the output per unit amplitude, capture by
capture (N×3, g), with a shape drawn per case (per-axis weights, a boundary plateau, the
outlier's rows). Its size is set by ``detectable_amplitude``: the amplitude at which the
pattern, after projecting out the base model's columns — per axis, the bias and the three
input columns of the gain matrix, each cubic in the recorded temperature (16 columns), every
capture weighted by the error gen3 drew into it (sd/√n as drawn, plus a hand fixture's
re-seating turn) — has noncentrality z², z the one-sided normal quantile at α = 0.005: a
test of that known pattern at α = 0.005 then has 50 % power. An ``outlier`` reading's place
is not known to a test, so its z is at α = 0.005/N (Bonferroni over the N readings). A
case is drawn at ``size`` × that amplitude; where the base model leaves less than 10⁻⁶ of
the pattern's weighted sum of squares (a per-plateau offset on 4 plateaus, which a cubic
in T interpolates; products of inputs on the 6 faces, all zero) the effect is not drawn
(``absorbed``).

Effects: ``temperature_sensor`` (the channel reads δ higher from plateau k on, before its
quantiser), ``scale_nonlinearity`` (K2·f² + K3·f³ per axis on the axis' own input),
``thermal_hysteresis`` (±h per axis by the direction of the last temperature excursion;
a one-way staircase is turned, at random, into one up-down cycle — up through alternate
setpoints, down through the rest — or a zigzag, up two and down one, whose direction
alternates plateau by plateau; a random order is kept),
``bias_drift`` (rate per axis × elapsed hours), ``outlier`` (1–3 captures shifted, each
in its own plateau, not the first or last reading), ``cross_coupling`` (K_ij·f_i·f_j into
both axes of the pair), ``session_offset`` (one power cycle between two plateaus: a bias
jump per axis from plateau k on; no ``session`` column, docs/recording.md has none),
``vibration_rectification`` (c·σ²_vib per axis, σ²_vib the vibration's variance that
``sd_*`` shows; a case drawn without vibration gets one). Not drawn: ``temperature_rate``
(gen3 captures after the step has settled below 1 % of the noise; dT/dt is then only the
controller ripple through the die's lag, far below what a channel of 0.01–0.5 °C LSB
resolves) and ``turntable_geometry`` (gen3's table has directions, not poses: a tilt of
its base has no frame to live in).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import norm

from benchmarks.blind.gen3.case import Case, simulate
from benchmarks.blind.gen3.noise import Vibration, _unit, _vibration_freq
from benchmarks.blind.gen3.protocol import Protocol
from benchmarks.blind.gen3.sensor import T_REF_C

ALPHA = 0.005
ABSORBED_SHARE = 1e-6  # below this share of the pattern left after the base: not drawn
EFFECTS = ("temperature_sensor", "scale_nonlinearity", "thermal_hysteresis", "bias_drift",
           "outlier", "cross_coupling", "session_offset", "vibration_rectification")
NOT_DRAWN = {
    "temperature_rate": "captures start after the step has settled below 1 % of the noise: "
    "dT/dt is only the controller ripple through the die's lag",
    "turntable_geometry": "gen3's table has directions, not poses: no frame for a tilt",
}


# ---- the size rule -------------------------------------------------------------------

def base_columns(rows: list[dict[str, Any]]) -> np.ndarray:
    """(N, 16): [1, f_x, f_y, f_z] × [1, τ, τ², τ³], τ = (sensor_c − 20 °C)/50 °C, f the
    row's reference: the bias and the gain matrix's columns, cubic in the recorded
    temperature, as the 12-parameter model with cubic thermal terms spans them."""
    t = (np.array([r["sensor_c"] for r in rows]) - T_REF_C) / 50.0
    ref = np.array([[r["ref_x"], r["ref_y"], r["ref_z"]] for r in rows])
    inputs = np.c_[np.ones(len(rows)), ref]
    powers = np.c_[np.ones_like(t), t, t**2, t**3]
    return (inputs[:, :, None] * powers[:, None, :]).reshape(len(rows), 16)


def drawn_sigma_g(rows: list[dict[str, Any]], place_max_rad: float = 0.0) -> np.ndarray:
    """(N, 3) each capture's drawn error σ per axis: sd/√n as drawn, plus a re-seating turn
    by an angle uniform in [0, max] about a random axis ((max²/3)·(1 − f_i²)/3)."""
    sd = np.array([[r["sd_x"], r["sd_y"], r["sd_z"]] for r in rows])
    n = np.array([r["n"] for r in rows], dtype=float)[:, None]
    ref = np.array([[r["ref_x"], r["ref_y"], r["ref_z"]] for r in rows])
    seat = place_max_rad**2 / 3.0 * (1.0 - ref**2) / 3.0
    return np.sqrt(sd**2 / n + seat)


@dataclass(frozen=True)
class ChannelNoise:
    """The temperature channel's own drawn error, seen in the output along ∂output/∂T
    (``slope``, N×3, g/°C): per capture the mean of n noisy samples (variance σ_c²/n,
    ``capture_var``), per plateau the rounding a quantiser leaves in that mean when its
    noise does not dither it (``plateau_var``, the same die position between two codes for
    the whole plateau), plateau by plateau (``steps``)."""

    slope: np.ndarray
    capture_var: float
    plateau_var: float
    steps: np.ndarray


def rounding_variance(lsb_c: float, noise_c: float, terms: int = 200) -> float:
    """Variance over the die's place between two codes of the bias a quantiser of step q
    leaves in the mean of samples with Gaussian noise σ: Σ_k q²/(2π²k²)·e^(−4π²k²σ²/q²)
    (q²/12 without noise, → 0 once σ ≳ q/2)."""
    k = np.arange(1, terms + 1)
    return float(np.sum(lsb_c**2 / (2 * np.pi**2 * k**2)
                        * np.exp(-4 * np.pi**2 * k**2 * noise_c**2 / lsb_c**2)))


def channel_noise(case: Case, rows: list[dict[str, Any]]) -> ChannelNoise:
    """The case's temperature channel error as ``ChannelNoise`` on its null rows."""
    s, th = case.sensor, case.thermal
    h = 0.01
    slope = np.array([(s.output_g(np.array([r["ref_x"], r["ref_y"], r["ref_z"]]),
                                  r["die_c"] + h)
                       - s.output_g(np.array([r["ref_x"], r["ref_y"], r["ref_z"]]),
                                    r["die_c"] - h)) / (2 * h) for r in rows])
    return ChannelNoise(slope=slope, capture_var=th.channel_noise_c**2 / case.noise.n,
                        plateau_var=rounding_variance(th.channel_lsb_c, th.channel_noise_c),
                        steps=np.array([r["step"] for r in rows]))


def noncentrality(rows: list[dict[str, Any]], pattern: np.ndarray,
                  place_max_rad: float = 0.0, channel: ChannelNoise | None = None) -> float:
    """The pattern's noncentrality after the base model, by generalised least squares
    against the drawn noise: min over the base coefficients β (free, per axis) and the
    channel's plateau errors u (prior variance ``plateau_var``) of
    |(pattern − Xβ − slope·u)/σ|² + |u|²/plateau_var, σ² = sd²/n (+ re-seating) +
    slope²·capture_var. Without ``channel``: Σ over axes of |P⊥(pattern/σ)|²."""
    x = base_columns(rows)
    sigma = drawn_sigma_g(rows, place_max_rad)
    if channel is not None:
        sigma = np.sqrt(sigma**2 + channel.slope**2 * channel.capture_var)
    n = len(rows)
    blocks, target = [], []
    for a in range(3):
        cols = np.zeros((n, 48))
        cols[:, 16 * a:16 * (a + 1)] = x / sigma[:, a:a + 1]
        blocks.append(cols)
        target.append(pattern[:, a] / sigma[:, a])
    design, rhs = np.vstack(blocks), np.concatenate(target)
    if channel is not None and channel.plateau_var > 1e-12:
        plateaus = np.unique(channel.steps)
        g = np.zeros((3 * n, plateaus.size))
        for j, k in enumerate(plateaus):
            on = channel.steps == k
            for a in range(3):
                g[a * n:(a + 1) * n, j] = np.where(on, channel.slope[:, a] / sigma[:, a], 0.0)
        prior = np.zeros((plateaus.size, 48 + plateaus.size))
        prior[:, 48:] = np.eye(plateaus.size) / np.sqrt(channel.plateau_var)
        design = np.vstack([np.hstack([design, g]), prior])
        rhs = np.r_[rhs, np.zeros(plateaus.size)]
    coef, *_ = np.linalg.lstsq(design, rhs, rcond=None)
    return float(np.sum((rhs - design @ coef) ** 2))


def detectable_amplitude(rows: list[dict[str, Any]], pattern: np.ndarray,
                         place_max_rad: float = 0.0, alpha: float = ALPHA,
                         channel: ChannelNoise | None = None) -> float:
    """z_{1−α}/√λ: the amplitude of ``pattern`` (per unit) a one-sided test at α detects
    half the time; inf when the base model absorbs it entirely."""
    lam = noncentrality(rows, pattern, place_max_rad, channel)
    return float(norm.ppf(1.0 - alpha) / np.sqrt(lam)) if lam > 1e-24 else float("inf")


# ---- the effects ---------------------------------------------------------------------

def _weights(rng: np.random.Generator, k: int = 3) -> np.ndarray:
    """Per-axis weights: random sign, magnitude 0.3–1."""
    return rng.choice([-1.0, 1.0], k) * rng.uniform(0.3, 1.0, k)


def _boundary(rng: np.random.Generator, plateaus: int) -> int:
    """A plateau index k with at least two plateaus before and after it (k = 1 … when
    there are fewer than four)."""
    if plateaus >= 4:
        return int(rng.integers(2, plateaus - 1))
    return max(1, plateaus - 1)


def excursion_directions(setpoints: tuple[float, ...], start_c: float = 20.0) -> np.ndarray:
    """+1 where a plateau was reached by heating, −1 by cooling (from ``start_c``)."""
    prev = np.r_[start_c, setpoints[:-1]]
    d = np.sign(np.asarray(setpoints) - prev)
    d[d == 0] = 1.0
    return d


def up_down(setpoints: tuple[float, ...]) -> tuple[float, ...]:
    """One cycle: an up leg through alternate setpoints (coldest first), then down through
    the rest."""
    sp = sorted(setpoints)
    return tuple(sp[0::2]) + tuple(sp[1::2][::-1])


def zigzag(setpoints: tuple[float, ...]) -> tuple[float, ...]:
    """Up two, down one: s0, s2, s1, s4, s3, … of the sorted setpoints, so the direction
    of the last excursion alternates from plateau to plateau."""
    sp = sorted(setpoints)
    idx = [0]
    for j in range(1, len(sp), 2):
        idx += [j + 1, j] if j + 1 < len(sp) else [j]
    return tuple(sp[i] for i in idx)


@dataclass
class Drawn:
    """One effect on one case: its prepared case, per-unit pattern and parameters."""

    name: str
    case: Case
    params: dict[str, Any]
    amplitude: float = 0.0  # in the effect's unit (see ``unit``)
    unit: str = ""
    channel: np.ndarray | None = None  # per-row channel step per unit (temperature_sensor)
    outlier_rows: tuple[int, ...] = ()
    outlier_dirs: np.ndarray | None = None
    outlier_amps: np.ndarray | None = None
    rng: np.random.Generator | None = None  # the effect's own draws
    rows: list[dict[str, Any]] = dataclasses.field(default_factory=list)  # the null rows

    # what the effect adds per unit amplitude at one capture
    def unit_g(self, i: int, force: np.ndarray, die_c: float, vib_var: np.ndarray,
               row: dict[str, Any]) -> np.ndarray:
        p, s = self.params, self.case.sensor
        if self.name == "scale_nonlinearity":
            return np.asarray(p["k2_w"]) * force**2 + np.asarray(p["k3_w"]) * force**3
        if self.name == "cross_coupling":
            kxy, kxz, kyz = p["k_w"]
            fx, fy, fz = force
            return np.array([kxy * fx * fy + kxz * fx * fz, kxy * fx * fy + kyz * fy * fz,
                             kxz * fx * fz + kyz * fy * fz])
        if self.name == "thermal_hysteresis":
            return np.asarray(p["w"]) * p["direction"][row["step"]]
        if self.name == "bias_drift":
            return np.asarray(p["w"]) * row["t_s"] / 3600.0
        if self.name == "session_offset":
            return np.asarray(p["w"]) * float(row["step"] >= p["from_step"])
        if self.name == "vibration_rectification":
            return np.asarray(p["w"]) * vib_var
        if self.name == "temperature_sensor":
            # the channel reads +1 °C: the output is read against T + 1, so it looks off by
            # −∂output/∂T (at the capture's force and die temperature)
            if row["step"] < p["from_step"]:
                return np.zeros(3)
            h = 0.01
            return -(s.output_g(force, die_c + h) - s.output_g(force, die_c - h)) / (2 * h)
        raise ValueError(self.name)

    def pattern(self, rows: list[dict[str, Any]]) -> np.ndarray:
        """(N, 3) per unit amplitude on the prepared case's null rows."""
        ref = np.array([[r["ref_x"], r["ref_y"], r["ref_z"]] for r in rows])
        return np.array([self.unit_g(i, ref[i], r["die_c"], r["vib_var"], r)
                         for i, r in enumerate(rows)])

    # the hook simulate() calls (nothing drawn)
    def extra_g(self, i: int, force: np.ndarray, die_c: float,
                vib_var: np.ndarray) -> np.ndarray:
        if self.name == "outlier":
            out = np.zeros(3)
            for k, row in enumerate(self.outlier_rows):
                if row == i:
                    out = out + self.outlier_amps[k] * self.outlier_dirs[k]
            return out
        if self.name == "temperature_sensor":
            return np.zeros(3)
        return self.amplitude * self.unit_g(i, force, die_c, vib_var, self.rows[i])

    def channel_c(self, i: int) -> float:
        if self.channel is None:
            return 0.0
        return float(self.amplitude * self.channel[i])


def prepare(name: str, case: Case) -> tuple[Drawn, dict[str, str]]:
    """The case the effect is drawn on (changed only where the effect needs it: an up and
    a down leg for hysteresis, vibration for its rectification) and the effect's shape;
    the draws come from the case's own seed, stream 2, never from the null's streams."""
    rng = np.random.default_rng([case.seed, 2, EFFECTS.index(name)])
    changed: dict[str, str] = {}
    plateaus = len(case.protocol.setpoints_c)
    params: dict[str, Any] = {}
    if name == "thermal_hysteresis":
        if case.protocol.order != "random":
            order = "updown" if rng.uniform() < 0.5 else "zigzag"
            sp = (up_down if order == "updown" else zigzag)(case.protocol.setpoints_c)
            prot: Protocol = dataclasses.replace(case.protocol, setpoints_c=sp, order=order)
            case = dataclasses.replace(case, protocol=prot)
            changed["order"] = f"one-way staircase made {order}"
        params["direction"] = excursion_directions(case.protocol.setpoints_c)
        params["w"] = _weights(rng)
    elif name == "vibration_rectification":
        nz = case.noise
        if nz.vibration is None:
            vib = Vibration(rms_g=float(rng.uniform(0.2e-3, 2e-3)), direction=_unit(rng),
                            common_share=float(rng.uniform(0.3, 1.0)),
                            freq_common_hz=float(_vibration_freq(rng, nz.odr_hz, nz.n, 1)[0]),
                            freq_axes_hz=_vibration_freq(rng, nz.odr_hz, nz.n, 3))
            case = dataclasses.replace(case, noise=dataclasses.replace(nz, vibration=vib))
            changed["vibration"] = "added (the null had none)"
        params["w"] = _weights(rng)
    elif name == "scale_nonlinearity":
        params["k2_w"], params["k3_w"] = _weights(rng), _weights(rng)
    elif name == "cross_coupling":
        params["k_w"] = _weights(rng)
    elif name in ("bias_drift",):
        params["w"] = _weights(rng)
    elif name in ("session_offset", "temperature_sensor"):
        params["from_step"] = _boundary(rng, plateaus)
        if name == "session_offset":
            params["w"] = _weights(rng)
    elif name != "outlier":
        raise ValueError(f"unknown effect {name!r}")
    return Drawn(name=name, case=case, params=params, unit=UNITS[name], rng=rng), changed


UNITS = {"temperature_sensor": "°C", "scale_nonlinearity": "g/g² (K2 and K3 weights)",
         "thermal_hysteresis": "g", "bias_drift": "g/h", "outlier": "g",
         "cross_coupling": "g/g²", "session_offset": "g",
         "vibration_rectification": "1/g (g per g² of vibration variance)"}


def draw_effect(name: str, case: Case, size: float) -> tuple[Drawn, dict[str, Any]]:
    """The effect on ``case`` at ``size`` × its detectable amplitude, and a summary of its
    draw (parameters, detectable amplitude, the case's changes)."""
    d, changed = prepare(name, case)
    rows0 = simulate(d.case)
    d.rows = rows0
    place = d.case.protocol.place_max_rad
    chan = channel_noise(d.case, rows0)
    info: dict[str, Any] = {"effect": name, "size": size, "changed": changed}
    if name == "outlier":
        rng = d.rng
        chosen = _outlier_rows(rng, rows0)
        dirs = np.array([_unit(rng) for _ in chosen])
        n = len(rows0)
        dets = []
        for row, u in zip(chosen, dirs, strict=True):
            pat = np.zeros((n, 3))
            pat[row] = u
            dets.append(detectable_amplitude(rows0, pat, place, alpha=ALPHA / n,
                                             channel=chan))
        d.outlier_rows, d.outlier_dirs = tuple(chosen), dirs
        d.outlier_amps = size * np.array(dets)
        info.update(detectable=[round(x * 1e6, 2) for x in dets], unit="µg",
                    rows=list(chosen), amplitude=[round(x * 1e6, 2) for x in d.outlier_amps])
        return d, info
    pattern = d.pattern(rows0)
    if name == "temperature_sensor":
        d.channel = np.array([float(r["step"] >= d.params["from_step"]) for r in rows0])
    total = float(np.sum((pattern / drawn_sigma_g(rows0, place)) ** 2))
    share = noncentrality(rows0, pattern, place) / total if total > 0 else 0.0
    absorbed = share < ABSORBED_SHARE
    det = float("inf") if absorbed else detectable_amplitude(rows0, pattern, place,
                                                             channel=chan)
    d.amplitude = 0.0 if absorbed else size * det
    info.update(detectable=det, amplitude=d.amplitude, unit=d.unit, share_left=share,
                absorbed=absorbed,
                params={k: (v.tolist() if isinstance(v, np.ndarray) else v)
                        for k, v in d.params.items()},
                effect_rms_ug=round(float(np.sqrt(np.mean((d.amplitude * pattern) ** 2)))
                                    * 1e6, 3))
    return d, info


def _outlier_rows(rng: np.random.Generator, rows: list[dict[str, Any]]) -> list[int]:
    """1–3 rows, each in its own plateau, not a plateau's first or last reading."""
    steps = np.array([r["step"] for r in rows])
    plateaus = list(np.unique(steps))
    k = min(int(rng.integers(1, 4)), len(plateaus))
    out = []
    for s in rng.choice(plateaus, k, replace=False):
        idx = np.flatnonzero(steps == s)
        inner = idx[1:-1] if idx.size > 2 else idx
        out.append(int(rng.choice(inner)))
    return sorted(out)
