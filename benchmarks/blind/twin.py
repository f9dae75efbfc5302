"""Run the offline twin (``simulators/campaign_sim``) for a protocol, with or without a
concealed effect, and compute an effect's noise-free signature and minimum detectable size."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from benchmarks.blind import detectability
from benchmarks.blind.catalogue import DF, NONLINEAR, ROWWISE, Concealed, make
from benchmarks.blind.protocols import Protocol
from calibration.recording import Recording
from simulators.campaign_sim import SimCampaign, simulate_campaign
from simulators.effects import ThermalLag
from simulators.truth import Context, SensorTruth

SAMPLES = 200


def run(protocol: Protocol, truth: SensorTruth, concealed: Concealed | None, seed: int
        ) -> SimCampaign:
    """One campaign; the concealed effect goes into the truth (or the rig, for lag)."""
    ph = protocol.physics()
    t = replace(truth, effects=[])
    if concealed is not None:
        if isinstance(concealed.effect, ThermalLag):
            ph = concealed.effect.physics(ph)
        else:
            t.effects = [concealed.effect]
    sim = simulate_campaign(t, protocol.setpoints_c, protocol.refs(), protocol.soak_min, SAMPLES,
                            seed, physics=ph, temperature_columns=protocol.columns,
                            sessions=protocol.sessions(), return_truth=True)
    assert isinstance(sim, SimCampaign)
    return sim


def recording(protocol: Protocol, truth: SensorTruth, concealed: Concealed | None,
              seed: int) -> Recording:
    return run(protocol, truth, concealed, seed).recording


def _context(protocol: Protocol, truth: SensorTruth, tau_s: float | None = None) -> Context:
    c = None if tau_s is None else Concealed(ThermalLag(tau_s), {})
    return run(protocol, truth, c, 0).extra["context"]


def signature(protocol: Protocol, truth: SensorTruth, concealed: Concealed,
              ctx0: Context) -> np.ndarray:
    """Noise-free change of the output relative to the base model at the recorded T, (N,3) g."""
    uses_sensor_c = "sensor_c" in protocol.columns
    if isinstance(concealed.effect, ThermalLag):
        if uses_sensor_c:  # regressed on the die temperature: lag is gone
            return np.zeros_like(ctx0.ref_g)
        ctx1 = _context(protocol, truth, concealed.effect.tau_s)
        return truth.ideal_raw_g(ctx0.ref_g, ctx1.die_c) - truth.ideal_raw_g(
            ctx0.ref_g, ctx0.die_c)
    rng = np.random.default_rng(0)
    x = concealed.effect.raw_delta_g(ctx0, truth, rng)
    if uses_sensor_c:
        td = concealed.effect.temperature_delta_c(ctx0, rng)
        if np.any(td):
            x = x - (truth.ideal_raw_g(ctx0.ref_g, ctx0.die_c + td)
                     - truth.ideal_raw_g(ctx0.ref_g, ctx0.die_c))
    return x


def lambda_fn(effect_id: str, pattern: dict, protocol: Protocol, truth: SensorTruth):
    """λ(m) for this effect/pattern/sensor under the protocol (see detectability.py)."""
    ctx0 = _context(protocol, truth)
    T_rec = ctx0.die_c if "sensor_c" in protocol.columns else ctx0.air_c
    sigma = np.sqrt(truth.sample_sd_g() ** 2 + ctx0.vib_sd_g**2) / np.sqrt(ctx0.n_samples)

    def lam(m: float) -> float:
        x = signature(protocol, truth, make(effect_id, m, pattern, protocol), ctx0)
        return detectability.noncentrality(x, ctx0.ref_g, T_rec, sigma)

    return lam


def row_lambdas(effect_id: str, pattern: dict, protocol: Protocol, truth: SensorTruth,
                m: float = 1.0) -> np.ndarray:
    """Per-reading λ_i at magnitude m (row-wise effects; see detectability.py)."""
    ctx0 = _context(protocol, truth)
    T_rec = ctx0.die_c if "sensor_c" in protocol.columns else ctx0.air_c
    sigma = np.sqrt(truth.sample_sd_g() ** 2 + ctx0.vib_sd_g**2) / np.sqrt(ctx0.n_samples)
    x = signature(protocol, truth, make(effect_id, m, pattern, protocol), ctx0)
    return detectability.row_noncentralities(x, ctx0.ref_g, T_rec, sigma)


def minimum_detectable_single_test(effect_id: str, pattern: dict, protocol: Protocol,
                                   truth: SensorTruth) -> float:
    """The criterion without the search over readings (λ of all of them in one df test)."""
    lam = lambda_fn(effect_id, pattern, protocol, truth)
    return detectability.minimum_detectable(lam, linear=True, df=DF[effect_id])


def minimum_detectable(effect_id: str, pattern: dict, protocol: Protocol,
                       truth: SensorTruth) -> float:
    """Magnitude (catalogue.UNIT) at 50 % power, α = 0.01 over the catalogue's candidates
    (and, for row-wise effects, over the readings that must be searched)."""
    if effect_id in ROWWISE:
        lam_rows = row_lambdas(effect_id, pattern, protocol, truth)
        rows = [int(r) for r in pattern["rows"]]
        return detectability.minimum_detectable_rows(lam_rows[rows], ROWWISE[effect_id],
                                                     lam_rows.size)
    lam = lambda_fn(effect_id, pattern, protocol, truth)
    if effect_id in NONLINEAR:
        return detectability.minimum_detectable(lam, linear=False, df=DF[effect_id],
                                                lo=1.0, hi=20000.0)
    return detectability.minimum_detectable(lam, linear=True, df=DF[effect_id])
