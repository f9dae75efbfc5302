"""Outside-catalogue effects the diagnosis was never developed on (issue 22, "checked again on
effects you have not seen").

``generate --outside-set unseen`` writes these instead of ``adc_band`` and ``crack``. Each is a
thing a real rig shows that the catalogue (docs/effects.md) has no id for, written from its
physical description only, as an additive output change (N,3) in g at a reading's state:

* ``fixture_creep`` — the fixture relaxes after every turn: each move loads it by the change
  of the gravity direction it carries, ``|ref_j − ref_(j−1)|/2`` (0…1), and the output creeps
  back with one time constant τ (20–120 s); the readings that follow within a few τ carry
  the sum of the kicks still decaying. Pose-dependent, time-dependent, never a rotation.
* ``thermal_threshold`` — a bias that jumps by m when the die is above T* (a package or
  solder phase change): a function of the die temperature with a step at T*, re-occurring
  on every crossing in both directions (unlike a power cycle); T* between two setpoints.
* ``hvac_cycle`` — a periodic disturbance in time from the chamber's air handler or
  compressor duty cycle: ``m·w·(sin φ(t) + 0.3·sin 2φ(t))``, φ = 2πt/P + φ0, P 10–40 min.
* ``frost`` — condensation/frost below the dew point T_d: a deposited mass F that grows
  toward 1 with τ_grow (1–2 h) while the die is below T_d and sublimates with τ_decay
  (10–30 min) above it; the output moves by m·w·F.
* ``cable_strain`` — a cable wound round the inner table axis pulls on the package by an
  amount that depends on the table angle α, not on the force the sensor sees:
  ``m·w·sin(α + φ)``; at β = 0 or 180° several α give one gravity direction and different
  offsets.

A random-walk (flicker) bias is not here: the catalogue's ``bias_drift`` names "random walk"
among its physics (docs/effects.md), so naming it ``bias_drift`` is not a wrong name.

Parameters (τ, T*, P, T_d, φ) are drawn from their own generator seeded by the case
(``unseen_pattern``), so the default cases' draws are untouched. Sizes: ``generate`` puts
each case at twice its minimum detectable size under its own protocol (detect.py's λ with
``DOF`` below), so no case is invisible.
"""

from __future__ import annotations

import numpy as np

UNSEEN_OUTSIDE = ("fixture_creep", "thermal_threshold", "hvac_cycle", "frost", "cable_strain")
UNIT = {e: "ug" for e in UNSEEN_OUTSIDE}
# Degrees of freedom of the λ test that sizes a case (detect.py): a per-axis pattern w.
DOF = {e: 3 for e in UNSEEN_OUTSIDE}
SIZE_MULTIPLE = 2.0


def unseen_pattern(seed: int, setpoints_c: tuple[float, ...]) -> dict:
    """The effect parameters of one case, drawn from the case's own generator."""
    rng = np.random.default_rng([seed, 22])
    sp = np.unique(np.asarray(setpoints_c, float))
    gaps = (sp[1:] + sp[:-1]) / 2.0
    inner = gaps[1:-1] if len(gaps) > 2 else gaps
    cold = sp[sp < 5.0]
    # the dew point lies above the coldest plateau (frost forms) and below 5 °C
    t_dew = float(rng.uniform(cold.min() + 3.0, 5.0)) if cold.size else float(sp.min() + 3.0)
    return {"creep_tau_s": float(rng.uniform(20.0, 120.0)),
            "threshold_c": float(rng.choice(inner)),
            "hvac_period_s": float(rng.uniform(10.0, 40.0) * 60.0),
            "hvac_phase_rad": float(rng.uniform(0.0, 2 * np.pi)),
            "dew_c": t_dew, "frost_grow_s": float(rng.uniform(3600.0, 7200.0)),
            "frost_decay_s": float(rng.uniform(600.0, 1800.0)),
            "cable_phase_rad": float(rng.uniform(0.0, 2 * np.pi))}


def creep_load(ref_g: np.ndarray, t_s: np.ndarray, capture_s: float, tau_s: float) -> np.ndarray:
    """Σ_j |ref_j − ref_(j−1)|/2 · exp(−(t_i − t_j)/τ) over the moves j ≤ i (t_j: the end of
    move j, half a capture before reading j; the first move starts from ref = (0, 0, 1))."""
    prev = np.vstack([[0.0, 0.0, 1.0], ref_g[:-1]])
    kick = np.linalg.norm(ref_g - prev, axis=1) / 2.0
    t_move = t_s - capture_s / 2.0
    out = np.zeros(len(t_s))
    for i in range(len(t_s)):  # why a loop: a causal sum, a few hundred readings
        dt = t_s[i] - t_move[: i + 1]
        out[i] = np.sum(kick[: i + 1] * np.exp(-dt / tau_s))
    return out


def frost_mass(die_trace_c: np.ndarray, dew_c: float, grow_s: float,
               decay_s: float) -> np.ndarray:
    """Deposited mass F (0…1) on the 1 s grid: dF/dt = (1 − F)/τ_grow below the dew point,
    −F/τ_decay above it (exact per-second steps)."""
    g, d = np.exp(-1.0 / grow_s), np.exp(-1.0 / decay_s)
    f = np.zeros(len(die_trace_c))
    for i in range(1, len(f)):  # why a loop: a state that switches its time constant
        f[i] = 1.0 - (1.0 - f[i - 1]) * g if die_trace_c[i - 1] < dew_c else f[i - 1] * d
    return f


def unseen_offset_g(eid: str, m: float, pat: dict, s: dict) -> np.ndarray:
    """Extra output (N,3) g of an unseen outside effect at the readings' state ``s``
    (ref_g, t_s, die_c, die_trace_c, angles_rad, capture_s); zeros for any other id."""
    w = np.asarray(pat["axes"])
    n = len(s["t_s"])
    if eid == "fixture_creep":
        shape = creep_load(s["ref_g"], s["t_s"], s["capture_s"], pat["creep_tau_s"])
    elif eid == "thermal_threshold":
        shape = (s["die_c"] > pat["threshold_c"]).astype(float)
    elif eid == "hvac_cycle":
        ph = 2 * np.pi * s["t_s"] / pat["hvac_period_s"] + pat["hvac_phase_rad"]
        shape = np.sin(ph) + 0.3 * np.sin(2 * ph)
    elif eid == "frost":
        f = frost_mass(s["die_trace_c"], pat["dew_c"], pat["frost_grow_s"],
                       pat["frost_decay_s"])
        shape = f[np.clip(np.round(s["t_s"]).astype(int), 0, len(f) - 1)]
    elif eid == "cable_strain":
        shape = np.sin(s["angles_rad"][:, 0] + pat["cable_phase_rad"])
    else:
        return np.zeros((n, 3))
    return shape[:, None] * w * m * 1e-6
