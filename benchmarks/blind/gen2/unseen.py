"""Protocols the second generator's default family never draws (issue 22, "checked again on
protocols you have not seen").

``draw_protocol(rng, ..., family="unseen")`` lands here. Each protocol is the default
family's kind of campaign (a staircase up, down, up-down or in random order; 6–11 setpoints
from −40…−20 to 50…70 °C; 10/20/45 min soaks; 20–200 samples) with ONE variant a real lab
runs and the default family does not, named first in the protocol's name:

* schedules: ``faces6`` (the six faces ±x ±y ±z), ``min12`` (4 β × 3 α, 12 positions),
  ``tri24`` (the seed paper's 24 positions parametrised another way: β offset by 22.5°, α
  at 30/150/270°), ``ring30`` (30 positions), ``dense48`` (48 positions);
* ``hand``: a hand-placed fixture, every visit re-seated with 1–3 mrad rms per axis; the
  recording declares it (``ref_tol_deg``, docs/recording.md), as a lab would;
* temperatures: ``narrow`` (0…40 °C), ``few`` (3 or 4 setpoints), ``unequal`` (setpoints
  at random spacing, at least 3 °C apart), ``repeat25`` (25 °C at the start and again at the
  end), ``hot_start`` (down from the hottest setpoint, then up again), ``soak5`` (5 min
  soaks: a die of τ 5–15 min still settling), ``soak90`` (90 min soaks);
* readings: ``n10`` and ``n1000`` samples per capture, ``quiet20`` and ``noisy300`` µg of
  sensor noise per sample;
* rigs: ``slowdie`` (a chamber_c-only column on a die of τ = 15 min, soaked 90 min = 6 τ;
  not a null: 0.02–0.07 °C of lag remain at the captures, so ``generate`` keys it as a
  ``slow_die`` case with the lag's size against its minimum detectable one; drawn only by
  name),
  ``offset_c`` (a sensor_c channel offset by 2–5 °C and quantised at 0.0625 °C, the
  ADXL355's temperature LSB class).

Two sensors per recording are not drawn: recording format v1 has one ``ax, ay, az`` triple
per row (docs/recording.md), so a second sensor is a second recording.
"""

from __future__ import annotations

import numpy as np

from benchmarks.blind.gen2 import protocol as pr

SCHEDULE_VARIANTS = ("faces6", "min12", "tri24", "ring30", "dense48")
OBLIQUE_SCHEDULES = ("tri24", "dense48")  # positions with two non-zero gravity components
# What each variant fixes (a draw's constraints must not fix the same thing).
TOUCHES: dict[str, frozenset[str]] = {
    **{s: frozenset({"schedule"}) for s in SCHEDULE_VARIANTS},
    "hand": frozenset(), "narrow": frozenset(), "few": frozenset(), "unequal": frozenset(),
    "repeat25": frozenset(), "hot_start": frozenset({"order"}),
    "soak5": frozenset({"soak"}), "soak90": frozenset({"soak"}),
    "n10": frozenset(), "n1000": frozenset(), "quiet20": frozenset(), "noisy300": frozenset(),
    "slowdie": frozenset({"columns", "soak"}), "offset_c": frozenset({"columns"}),
}
UNSEEN_KINDS = tuple(TOUCHES)
SHAPES = ("oneway", "staircase_down", "updown", "irregular")
SLOW_DIE_TAU_S = 900.0
FAST_DIE_S = 60.0  # the default family's chamber-only die: τ = 20 s, settled in any soak
ROOM_C = 25.0


def lagging_die(proto: pr.Protocol2) -> bool:
    """The model's only temperature is the chamber air while the die lags it by more than a
    fixture's seconds: the recording holds a die lag (``thermal_lag``), whatever the soak."""
    return tuple(proto.columns) == ("chamber_c",) and proto.die_tau_s > FAST_DIE_S


def _setpoints(rng: np.random.Generator, variant: str, shape: str) -> tuple[float, ...]:
    lo = float(rng.choice([-40.0, -30.0, -20.0]))
    hi = float(rng.choice([50.0, 60.0, 70.0]))
    n_t = int(rng.integers(6, 12))
    if variant == "narrow":
        lo, hi, n_t = 0.0, 40.0, 5
    elif variant == "few":
        n_t = int(rng.integers(3, 5))
    if variant == "unequal":
        while True:  # random spacing, ends kept, no two setpoints closer than 3 °C
            inner = np.sort(rng.uniform(lo, hi, n_t - 2))
            up_arr = np.round(np.concatenate([[lo], inner, [hi]]))
            if np.all(np.diff(up_arr) >= 3.0):
                break
    else:
        up_arr = np.round(np.linspace(lo, hi, n_t))
    up = tuple(float(x) for x in up_arr)
    if variant == "hot_start":
        sp = up[::-1] + up[1:]
    elif shape == "oneway":
        sp = up
    elif shape == "staircase_down":
        sp = up[::-1]
    elif shape == "updown":
        sp = up + up[-2::-1]
    else:
        sp = tuple(float(x) for x in rng.permutation(up))
    if variant == "repeat25":
        sp = (ROOM_C,) + tuple(x for x in sp if x != ROOM_C) + (ROOM_C,)
    return sp


def _variant(rng: np.random.Generator, kind: str | None, fixed: set[str],
             schedule: str | None) -> str:
    if kind in TOUCHES:
        return str(kind)
    # Why slowdie only by name: a chamber_c-only column on a 15 min die carries a die lag
    # (the thermal_lag effect itself); drawn under another effect, a case would hold two.
    ok = [v for v, t in TOUCHES.items() if v != "slowdie" and (
          not (t & fixed)
          or (t == {"schedule"} and schedule == "oblique36" and v in OBLIQUE_SCHEDULES))]
    if kind == "updown":
        ok = [v for v in ok if "order" not in TOUCHES[v]]
    return str(rng.choice(ok))


def draw_unseen(rng: np.random.Generator, kind: str | None = None,
                schedule: str | None = None, columns: tuple[str, ...] | None = None,
                soak_min: float | None = None) -> pr.Protocol2:
    """One protocol with one unseen variant. ``kind`` is a variant (``UNSEEN_KINDS``) or a
    default-family order (``updown`` …, a constraint an effect needs to show); the other
    constraints (schedule, columns, soak) are honoured, and a variant that would override one
    is not drawn (an oblique schedule may stand in for ``oblique36``)."""
    fixed = {k for k, v in (("schedule", schedule), ("columns", columns), ("soak", soak_min))
             if v is not None}
    variant = _variant(rng, kind, fixed, schedule)
    shape = str(kind) if kind in SHAPES else str(rng.choice(SHAPES))
    sp = _setpoints(rng, variant, shape)
    cols = columns or [("sensor_c",), ("chamber_c", "sensor_c"), ("chamber_c",)][
        int(rng.integers(0, 3))]
    soak = soak_min if soak_min is not None else float(rng.choice([10.0, 20.0, 45.0]))
    sched = schedule or str(rng.choice(["dense24", "sparse18", "oblique36"]))
    if variant in SCHEDULE_VARIANTS:
        sched = variant
    n_samples = int(rng.choice([20, 50, 100, 200]))
    noise_g = float(rng.uniform(40e-6, 120e-6))
    placement_rad, offset_c, lsb_c = 5e-6, 0.0, 0.1
    die_tau_s = None
    if variant == "hand":
        placement_rad = float(rng.uniform(1e-3, 3e-3))
    elif variant == "soak5":
        soak = 5.0
    elif variant == "soak90":
        soak = 90.0
    elif variant in ("n10", "n1000"):
        n_samples = int(variant[1:])
    elif variant == "quiet20":
        noise_g = 20e-6
    elif variant == "noisy300":
        noise_g = 300e-6
    elif variant == "slowdie":
        cols, soak, die_tau_s = ("chamber_c",), 90.0, SLOW_DIE_TAU_S
    elif variant == "offset_c":
        cols = ("sensor_c",) if "sensor_c" not in cols else cols
        offset_c = float(rng.uniform(2.0, 5.0) * rng.choice([-1.0, 1.0]))
        lsb_c = 0.0625
    if die_tau_s is None:
        die_tau_s = 20.0 if tuple(cols) == ("chamber_c",) else float(rng.uniform(300, 900))
    vib_level = float(rng.uniform(0.3e-3, 1.5e-3))
    vib = tuple(vib_level if t < 5.0 else (0.15e-3 if rng.random() < 0.2 else 0.0) for t in sp)
    return pr.Protocol2(
        name=f"{variant}/{sched}/{shape}/{'+'.join(cols)}/{soak:.0f}min", setpoints_c=sp,
        soak_min=soak, schedule=sched, columns=tuple(cols), die_tau_s=die_tau_s,
        n_samples=n_samples, vib_sd_g=vib,
        irregular=bool(shape == "irregular" or rng.random() < 0.3),
        power_cycle_at=len(sp) // 2 if shape == "updown" and variant != "hot_start" else None,
        sensor_noise_g=noise_g, placement_rad=placement_rad, sensor_c_offset_c=offset_c,
        sensor_c_lsb_c=lsb_c)
