"""What a recording's protocol can and cannot separate (issue 10, docs/diagnosis.md §11).

The facts come from the recording alone: how many plateaus and whether they are
reached one way or both ways (``DesignContext.one_way``), the position order on
each plateau (fixed, random or balanced: inferred from the ``t_s`` order within
steps, or from a ``visit`` column when present, with
:func:`~calibration.discrepancy.protocol_order.time_and_position_confounded`),
which temperature column the model uses, whether references and ``sd_*`` and a
``session`` column are recorded, and whether any position is oblique.

Each rule below is one pair (or group) of catalogue effects the protocol makes
look alike, with the reason in words. ``withhold`` marks the groups whose
members are each testable here but not from each other: a finding naming one of
them is reported as ``not_identifiable`` with every candidate (the spec's
"report it as not identifiable", effects.md). The other groups are stated in the
report; the finding keeps its name, as the better of the candidates the
diagnosis can test, and lists the untestable alternative.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from calibration.discrepancy.context import DesignContext
from calibration.discrepancy.protocol_order import time_and_position_confounded

THERMAL = ("thermal_lag", "thermal_hysteresis", "temperature_rate", "self_heating",
           "temperature_sensor")
ORIENTATION = ("scale_nonlinearity", "cross_coupling")
OBLIQUE_MIN = 0.05  # |a_i a_j| above this: some position loads two axes at once


@dataclass(frozen=True)
class Confusion:
    """Effects this protocol cannot tell apart, and why."""

    effects: tuple[str, ...]
    why: str
    withhold: bool = False  # a finding naming one of them is reported as not identifiable
    # Two sides (e.g. time-within-plateau terms versus orientation terms): only members of
    # opposite sides look alike. Empty: every member looks like every other.
    versus: tuple[str, ...] = ()
    # Rivals outside the catalogue (phrases, not effect ids): no finding can name them, so
    # they never become ``alternatives`` or ``confusers``; the report states them.
    outside: tuple[str, ...] = ()
    experiment: str = ""  # what would separate them, when ``why`` does not say it

    def alternatives(self, effect_id: str) -> list[str]:
        """The members that ``effect_id`` cannot be told from here."""
        if effect_id not in self.effects:
            return []
        if self.versus:
            side = self.versus if effect_id not in self.versus else \
                tuple(e for e in self.effects if e not in self.versus)
            return [e for e in side if e != effect_id]
        return [e for e in self.effects if e != effect_id]

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"effects": list(self.effects), "why": self.why,
                               "finding_withheld": self.withhold}
        if self.versus:
            out["versus"] = list(self.versus)
        if self.outside:
            out["outside_catalogue"] = list(self.outside)
        if self.experiment:
            out["experiment"] = self.experiment
        return out


@dataclass(frozen=True)
class Protocol:
    """The recording's protocol as the diagnosis sees it, and what it separates."""

    temperature: str  # "none" | "one plateau" | "one way" | "both ways"
    temperature_source: str  # "sensor_c" | "chamber_c" | "none"
    n_plateaus: int
    position_order: str  # "fixed" | "varied" | "balanced" | "one plateau"
    order_from: str  # "visit column" | "t_s within steps"
    references: bool
    sessions: int | None  # levels of the session column; None when not recorded
    sd_recorded: bool
    oblique: bool
    separable: tuple[str, ...] = ()
    table_poses: bool = False  # the pose_q* columns (calibration/table_pose.py) on every row
    not_separable: tuple[Confusion, ...] = field(default_factory=tuple)

    def withheld_with(self, effect_id: str) -> Confusion | None:
        """The withholding group that names ``effect_id``, if any."""
        return next((c for c in self.not_separable
                     if c.withhold and effect_id in c.effects), None)

    def with_testable(self, testable: dict[str, bool]) -> Protocol:
        """``separable``: the effects testable in this recording that no confusion holds."""
        named = {e for c in self.not_separable for e in c.effects}
        return replace(self, separable=tuple(e for e, ok in testable.items()
                                             if ok and e not in named))

    def to_json(self) -> dict[str, Any]:
        return {
            "temperature": self.temperature, "temperature_source": self.temperature_source,
            "n_plateaus": self.n_plateaus, "position_order": self.position_order,
            "order_from": self.order_from, "references": self.references,
            "sessions": self.sessions, "sd_recorded": self.sd_recorded,
            "oblique_positions": self.oblique, "table_poses": self.table_poses,
            "separable": list(self.separable),
            "not_separable": [c.to_json() for c in self.not_separable],
        }


def position_order_kind(steps: np.ndarray, positions: np.ndarray, t_s: np.ndarray,
                        visit: np.ndarray | None = None) -> str:
    """``fixed`` (same order on every plateau), ``balanced`` or ``varied``; ``one plateau``.

    ``balanced``: over the plateaus every position takes every visiting slot equally
    often, ±1 (a Latin/Williams square, protocol_order.py); ``varied``: orders differ
    without that balance. ``varied``, not ``random``: a recording does not say why its
    orders differ, and the engine's least-travel order (each plateau starting where the
    last one ended) differs between plateaus without being random. The order is
    ``visit`` when recorded, else ``t_s``. Only ``fixed`` changes what is separable; the
    other two are descriptive (with fewer plateaus than positions a lucky random order
    can read as balanced).
    """
    key = t_s if visit is None else visit
    ids = np.unique(steps)
    if ids.size < 2:
        return "one plateau"
    if time_and_position_confounded(steps, positions, key):
        return "fixed"
    pos_ids = np.unique(positions)
    slots = np.zeros((pos_ids.size, pos_ids.size), int)  # (position, slot) counts
    index = {int(p): k for k, p in enumerate(pos_ids)}
    for s in ids:
        m = steps == s
        order = positions[m][np.argsort(key[m], kind="stable")]
        for slot, p in enumerate(order[:pos_ids.size]):
            slots[index[int(p)], slot] += 1
    balanced = np.ptp(slots) <= 1  # each position in each slot as often as any other (±1)
    return "balanced" if balanced else "varied"


def assess(ctx: DesignContext, visit: np.ndarray | None = None,
           identifiable: dict[str, bool] | None = None) -> Protocol:
    """The protocol facts and the confusions they imply (docs/diagnosis.md §11).

    ``identifiable``: effect id → whether the effect alone can be tested here
    (``CatalogueEffect.identifiable``); it decides which confusions withhold a name, and
    ``separable`` lists those not in any confusion (``with_testable`` narrows it once the
    base model's absorbed fractions are known).
    """
    n_plateaus = len(ctx.step_ids)
    if ctx.temperature_source == "none":
        temperature = "none"
    elif n_plateaus < 2:
        temperature = "one plateau"
    else:
        temperature = "one way" if ctx.one_way else "both ways"
    order = position_order_kind(ctx.steps, ctx.positions, ctx.t_s, visit)
    a = ctx.input_g
    oblique = bool(ctx.n) and max(float(np.max(np.abs(a[:, i] * a[:, j])))
                                  for i, j in ((0, 1), (0, 2), (1, 2))) >= OBLIQUE_MIN
    sessions = None if ctx.session is None else int(np.unique(ctx.session).size)
    conf: list[Confusion] = []
    if temperature == "none":
        conf.append(Confusion(
            THERMAL + ("bias_drift",),
            "no temperature is recorded: nothing thermal can be seen, and a drift with elapsed "
            "time cannot be told from a slow change of an unrecorded temperature",
            versus=("bias_drift",)))
    read_once = np.unique(ctx.positions).size == ctx.n  # one plateau, no position repeated
    if order == "fixed" or (order == "one plateau" and read_once):
        how = ("the positions are visited in the same order on every plateau" if order == "fixed"
               else "one plateau: each position is read once, at one time")
        conf.append(Confusion(
            ("self_heating", "bias_drift") + ORIENTATION, versus=ORIENTATION,
            why=(f"{how}: time within a plateau (a self-heating warm-up, drift within each "
                 "plateau) and orientation are one regressor here; a seeded or balanced order "
                 "per plateau separates them")))
    rate_seen = identifiable is None or identifiable.get("temperature_rate", False)
    if temperature == "one way" and sessions is None and rate_seen:
        # Only where plateau slopes are measurable: at dT/dt ≈ 0 no rate term is in the data.
        conf.append(Confusion(
            ("temperature_rate", "session_offset", "thermal_hysteresis"),
            "a one-way staircase approaches every plateau from the same side, so a rate term "
            "(largest on the first plateau, one sign throughout) is a jump after the first "
            "plateau or a constant direction term; plateaus approached from both sides (or a "
            "recorded session column) separate them",
            withhold=True))
    if temperature == "one way" and sessions is None and temperature_changes(ctx):
        conf.append(power_cycle_is_a_jump_at_a_temperature())
    if temperature == "one way":
        conf.append(Confusion(
            ("bias_drift", "thermal_hysteresis"),
            "a one-way staircase makes elapsed time affine in temperature and the heating "
            "direction constant: the cubic in T and the bias absorb both"))
    if ctx.temperature_source == "sensor_c":
        conf.append(Confusion(
            ("thermal_lag", "self_heating", "temperature_sensor"),
            "the model's temperature is the sensor's own channel: a die lag, a die offset and "
            "a constant channel offset are re-mappings of T that the cubic absorbs (a step of "
            "the channel between plateaus is tested)"))
    if not oblique:
        conf.append(Confusion(
            ORIENTATION + ("turntable_geometry",),
            "axis-aligned positions only: a³ aliases into scale, a² partly into bias, and every "
            "product of two axes' inputs is zero"))
    if identifiable is not None:
        # Withhold a name only where two members could each be tested here: then the data
        # hold evidence for one of them without saying which. Otherwise the one testable
        # member is the only candidate and keeps its name.
        conf = [replace(c, withhold=c.withhold and sum(
            identifiable.get(e, False) for e in c.effects) >= 2) for c in conf]
    return Protocol(
        temperature=temperature, temperature_source=ctx.temperature_source,
        n_plateaus=n_plateaus, position_order=order,
        order_from="t_s within steps" if visit is None else "visit column",
        references=ctx.mode == "reference", sessions=sessions,
        sd_recorded=ctx.sd_g is not None, oblique=oblique,
        not_separable=tuple(conf),
        table_poses=ctx.pose_q is not None).with_testable(identifiable or {})


def temperature_changes(ctx: DesignContext) -> bool:
    """Some plateaus differ in temperature by more than ``DesignContext.one_way``'s 0.5 °C:
    a staircase, not one temperature held over several plateaus."""
    temps = np.asarray([ctx.step_temp_c[s] for s in ctx.step_ids], float)
    return temps.size > 1 and float(np.ptp(temps)) > 0.5


def power_cycle_is_a_jump_at_a_temperature() -> Confusion:
    """``session_offset`` without a session column on a one-way staircase (issue 22).

    The jump is profiled over plateau boundaries (``effects/session_offset.py``), and on a
    staircase that never comes back every plateau after boundary k is hotter (or colder)
    than every plateau before it: the jump's column is the per-axis jump where the
    temperature crosses a T* between plateaus k − 1 and k (``temperature_jump.py``), a rival
    outside the catalogue. This holds whether or not plateau slopes are measurable (the
    rate rule above needs them), so it is its own entry. It does not withhold: the finding
    is compared with that jump by fit in ``temperature_jump_alike``; the entry only says
    what the protocol cannot tell, and never adds a confuser (the rival is no effect id).
    """
    return Confusion(
        ("session_offset",),
        "without a session column a power cycle is seen only as a bias jump between two "
        "plateaus, and on a one-way staircase every plateau after the jump is hotter (or "
        "colder) than every plateau before it: the jump is the same per-axis offset as a jump "
        "of the output where the temperature crosses a T* between those plateaus",
        outside=("a jump of the output where the temperature crosses a T* (a package or "
                 "solder change at a temperature; outside the catalogue)",),
        experiment=("revisit a temperature after the power cycle (an up-down or repeated "
                    "staircase, or plateaus in a random temperature order: a jump at a "
                    "temperature re-occurs at every crossing, a power cycle once), or record "
                    "the power cycles in a session column"))


def visit_column(columns: dict[str, np.ndarray]) -> np.ndarray | None:
    """The recorded visiting order within each plateau, when the recording has one."""
    v = columns.get("visit")
    if v is None:
        return None
    v = np.asarray(v, float)
    return v if np.all(np.isfinite(v)) else None
