"""Sensor truth model: what an ADXL355-class accelerometer outputs (physics only, no wire).

* SFEM parameters (Eq. 1) are cubic polynomials of the **die** temperature
  (Eq. 8): ``p_k(T) = c0 + c1·dT + c2·dT² + c3·dT³`` with ``dT = T − 25 °C``.
* Raw output for a specific force ``f`` (g, sensor frame):
  ``raw = A(T)⁻¹ f + b(T)`` (the inverse of Eq. 1), plus white noise of
  density ``noise_density_ug_rthz`` over a bandwidth of ODR/2 per sample.
* The temperature channel reads the die temperature plus a constant offset
  (the ADXL355 channel is "not absolute") with its own noise, quantised at
  0.11 °C/LSB by the bridge.
* Extra physics of ``docs/effects.md`` enters through :class:`Effect`
  objects (see ``simulators/effects.py``), each adding to the raw output or to
  the temperature reading given a :class:`Context` of the readings.

Magnitudes of :meth:`SensorTruth.adxl355_typical` follow the datasheet:
offset ±25 mg, offset tempco 0.02 mg/°C typical, sensitivity tempco
0.01 %/°C, cross-axis ~1 %.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from calibration import sfem

T_REF_C = 25.0


@dataclass
class Context:
    """Everything an effect may depend on, one entry per reading (N readings)."""

    t_s: np.ndarray  # (N,) time since campaign start
    die_c: np.ndarray  # (N,) true die temperature
    air_c: np.ndarray  # (N,) chamber air temperature
    die_rate_c_per_s: np.ndarray  # (N,) dT_die/dt
    ref_g: np.ndarray  # (N,3) true specific force in the sensor frame
    step: np.ndarray  # (N,) campaign step index
    direction: np.ndarray  # (N,) +1 last excursion heating, −1 cooling, 0 unknown
    session: np.ndarray  # (N,) power-session index
    n_samples: np.ndarray  # (N,) samples averaged per reading
    vib_sd_g: np.ndarray  # (N,) rms vibration acceleration at the sensor (g)
    omega_rad_s: np.ndarray | None = None  # (N,3) table angular rate (None = static)
    # (N,3,3) Rᵀ of the table's pose (lab vectors into the sensor frame) as the rig holds it;
    # None: only the reference is known (a schedule without a table)
    lab_to_sensor: np.ndarray | None = None


class Effect(Protocol):
    """One piece of extra physics. ``effect_id`` is the catalogue id (effects.md)."""

    effect_id: str

    def raw_delta_g(self, ctx: Context, truth: SensorTruth, rng: np.random.Generator) -> np.ndarray:
        """Additive change of the (averaged) raw output, (N,3) g."""
        ...

    def temperature_delta_c(self, ctx: Context, rng: np.random.Generator) -> np.ndarray:
        """Additive change of the temperature channel reading, (N,) °C."""
        ...


@dataclass
class SensorTruth:
    """True behaviour of one sensor. ``coeffs`` is (12, 4): parameter k = poly in (T − 25 °C)."""

    coeffs: np.ndarray
    noise_density_ug_rthz: float = 25.0
    odr_hz: float = 62.5
    range_g: float = 2.0
    temp_offset_c: float = 0.0  # temperature channel reads die + offset
    temp_noise_c: float = 0.1  # rms per raw temperature sample
    serial: str = "SN-0001"
    effects: list[Effect] = field(default_factory=list)

    # --- construction -------------------------------------------------
    @classmethod
    def adxl355_typical(cls, seed: int = 0, **kw: object) -> SensorTruth:
        """A plausible ADXL355 drawn at random (datasheet magnitudes), reproducible by seed."""
        rng = np.random.default_rng(seed)
        c = np.zeros((sfem.N_PARAMS, 4))
        c[0:3, 0] = rng.uniform(-25e-3, 25e-3, 3)  # offset, g
        c[0:3, 1] = rng.normal(0, 0.05e-3, 3)  # offset tempco, g/°C (0.02 typ, 0.15 max mg/°C)
        c[0:3, 2] = rng.normal(0, 0.6e-6, 3)  # curvature, g/°C²
        c[0:3, 3] = rng.normal(0, 8e-9, 3)  # g/°C³
        c[3:6, 0] = 1.0 + rng.normal(0, 0.01, 3)  # sensitivity error ±1 %
        c[3:6, 1] = rng.normal(0, 1e-4, 3)  # 0.01 %/°C
        c[3:6, 2] = rng.normal(0, 1e-6, 3)
        c[3:6, 3] = rng.normal(0, 1e-8, 3)
        c[6:9, 0] = rng.normal(0, 4e-3, 3)  # non-orthogonality, rad (cross-axis ~1 %)
        c[6:9, 1] = rng.normal(0, 2e-6, 3)
        c[9:12, 0] = rng.normal(0, 5e-3, 3)  # mounting misalignment, rad
        c[9:12, 1] = rng.normal(0, 2e-6, 3)
        return cls(coeffs=c, temp_offset_c=float(rng.uniform(-2.0, 2.0)), **kw)  # type: ignore[arg-type]

    @classmethod
    def from_twin(cls, twin: object, **kw: object) -> SensorTruth:
        """The sensor of a twin document (``calibration.discrepancy.twin_file.Twin``).

        The twin's model polynomials (Eq. 8, in x = (T − centre)/scale up to degree 3)
        are re-expanded exactly in (T − 25 °C); its temperature is the die's, so the
        channel offset is 0. Noise: the twin's per-sample sd (mean over axes) as a density
        at this ODR, and its temperature-channel noise per reading scaled to one sample.
        Effects: the catalogue effects the twin carries, each its simulator counterpart
        (``simulators.effects.to_truth_effects``).
        """
        model = twin.model  # type: ignore[attr-defined]
        if model.degree > 3:
            raise ValueError(f"twin model degree {model.degree} > 3: the truth model is cubic")
        c = np.zeros((sfem.N_PARAMS, 4))
        x_of_u = np.polynomial.Polynomial([(T_REF_C - model.t_centre_c) / model.t_scale_c,
                                           1.0 / model.t_scale_c])
        for k in range(sfem.N_PARAMS):
            p = np.polynomial.Polynomial(model.coeffs[k])(x_of_u).coef
            c[k, : p.size] = p[:4]
        out = cls(coeffs=c, temp_offset_c=0.0, **kw)  # type: ignore[arg-type]
        ssd = getattr(twin, "sample_sd_g", None)
        if ssd:
            out.noise_density_ug_rthz = float(np.mean(ssd)) * 1e6 / np.sqrt(out.odr_hz / 2.0)
        tn = getattr(twin, "temperature_noise_c", None)
        n = getattr(twin, "samples_per_reading", None) or 1.0
        if tn is not None:
            out.temp_noise_c = float(tn) * float(np.sqrt(n))
        effects = getattr(twin, "effects", None) or []
        if effects:  # the catalogue effects the twin carries (twin_effects.py), as findings
            from simulators.effects import to_truth_effects

            out.effects = to_truth_effects(effects)  # type: ignore[assignment]
        return out

    # --- physics --------------------------------------------------------
    def params_vector_at(self, die_c: np.ndarray | float) -> np.ndarray:
        """SFEM parameter vectors at die temperature(s): (12,) or (N,12)."""
        dT = np.asarray(die_c, dtype=float) - T_REF_C
        powers = np.stack([np.ones_like(dT), dT, dT**2, dT**3], axis=-1)
        return powers @ self.coeffs.T

    def params_at(self, die_c: float) -> sfem.SfemParams:
        return sfem.SfemParams.from_vector(self.params_vector_at(float(die_c)))

    def sample_sd_g(self) -> float:
        """rms noise of one raw sample: density × √(ODR/2)."""
        return self.noise_density_ug_rthz * 1e-6 * np.sqrt(self.odr_hz / 2.0)

    def ideal_raw_g(self, ref_g: np.ndarray, die_c: np.ndarray | float) -> np.ndarray:
        """Noise-free raw output, base model only: raw = A(T)⁻¹ f + b(T). Shapes (N,3)."""
        f = np.atleast_2d(np.asarray(ref_g, dtype=float))
        T = np.broadcast_to(np.asarray(die_c, dtype=float), (f.shape[0],))
        return sfem.inverse(self.params_vector_at(T), f)

    def sample_g(
        self,
        ref_g: np.ndarray,
        die_c: float,
        n: int,
        rng: np.random.Generator,
        t_s: float = 0.0,
        lab_to_sensor: np.ndarray | None = None,
        die_rate_c_per_s: float = 0.0,
        direction: int = 0,
    ) -> np.ndarray:
        """``n`` raw samples (n,3) in g for one orientation at one die temperature.

        Effects are evaluated for one reading at ``t_s`` (the bridge simulator uses this
        path); saturated at ±range_g. ``lab_to_sensor``: the table's pose Rᵀ (3, 3)
        holding this orientation, when known (a tilted base reaches the sensor through
        it). ``die_rate_c_per_s`` and ``direction`` (+1 after heating, −1 after cooling,
        0 before any excursion): the die's motion, which a ``temperature_rate`` and a
        ``thermal_hysteresis`` effect act on (default: a die at rest, never moved).
        """
        ideal = self.ideal_raw_g(np.asarray(ref_g, float)[None, :], die_c)[0]
        if self.effects:
            ref = np.asarray(ref_g, float)[None, :]
            ctx = static_context(ref, np.array([die_c]), np.array([t_s]), n)
            ctx.die_rate_c_per_s = np.array([float(die_rate_c_per_s)])
            ctx.direction = np.array([int(direction)])
            if lab_to_sensor is not None:
                ctx.lab_to_sensor = np.asarray(lab_to_sensor, float)[None]
            for eff in self.effects:
                ideal = ideal + eff.raw_delta_g(ctx, self, rng)[0]
        samples = ideal + rng.normal(0.0, self.sample_sd_g(), size=(n, 3))
        # np.clip's bits, without its dispatch (a third of this call at 200 samples)
        np.minimum(samples, self.range_g, out=samples)
        return np.maximum(samples, -self.range_g, out=samples)

    def temperature_samples_c(self, die_c: float, n: int, rng: np.random.Generator) -> np.ndarray:
        return die_c + self.temp_offset_c + rng.normal(0.0, self.temp_noise_c, n)


def averaged_readings(truth: SensorTruth, ctx: Context, rng: np.random.Generator
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Averaged raw readings (N,3), their sample sd (N,3) and the temperature channel (N,)
    for the readings of ``ctx``: base model plus effects, then noise drawn from the
    sampling distribution of a mean of n samples (σ/√n; sd from a χ distribution; the
    channel's noise per sample over √n), exact for white noise and ~200× faster than
    drawing every sample. The twins' one way to make a reading (offline soak, ramp)."""
    N = ctx.t_s.size
    n = ctx.n_samples
    ideal = truth.ideal_raw_g(ctx.ref_g, ctx.die_c)
    temp_delta = np.zeros(N)
    for eff in truth.effects:
        ideal = ideal + eff.raw_delta_g(ctx, truth, rng)
        temp_delta = temp_delta + eff.temperature_delta_c(ctx, rng)
    sd1 = np.sqrt(truth.sample_sd_g() ** 2 + ctx.vib_sd_g**2)  # per-sample sd incl. vibration
    mean = ideal + rng.normal(size=(N, 3)) * (sd1 / np.sqrt(n))[:, None]
    sd = sd1[:, None] * np.sqrt(rng.chisquare(np.maximum(n - 1, 1)[:, None], (N, 3)) /
                                np.maximum(n - 1, 1)[:, None])
    sensor_c = (ctx.die_c + truth.temp_offset_c + temp_delta
                + rng.normal(size=N) * truth.temp_noise_c / np.sqrt(n))
    return mean, sd, sensor_c


def static_context(
    ref_g: np.ndarray, die_c: np.ndarray, t_s: np.ndarray, n: int | np.ndarray
) -> Context:
    """A Context for static readings with no step/direction information."""
    N = ref_g.shape[0]
    zeros = np.zeros(N)
    return Context(
        t_s=np.asarray(t_s, float),
        die_c=np.asarray(die_c, float),
        air_c=np.asarray(die_c, float),
        die_rate_c_per_s=zeros,
        ref_g=ref_g,
        step=np.zeros(N, int),
        direction=np.zeros(N, int),
        session=np.zeros(N, int),
        n_samples=np.broadcast_to(np.asarray(n), (N,)).astype(float),
        vib_sd_g=zeros,
    )
