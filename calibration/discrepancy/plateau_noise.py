"""The groups of entries whose noise a plateau shares (issue 22; docs/diagnosis.md §2).

Two components, each one Gaussian offset per group (:class:`stats.SharedGroups`), their
variances fitted to the recording's own residual (:func:`stats.shared_variance`):

* ``plateau x axis``: an offset per plateau and output axis (loading 1 on the whitened
  entries: chamber state, slow vibration, a sub-LSB offset of a quantised channel — what
  moves one axis of every reading of the plateau);
* ``plateau temperature``: one temperature error per plateau through the base model's
  ∂output/∂T (the die's error against the recorded temperature, which moves the three
  axes together in the base's own proportions).

Norm mode has one entry per reading: its first component is one offset per plateau.

One more component is *known*, not fitted (:func:`quantised_channel`): a temperature
channel quantised to an LSB q whose own noise is far below q does not dither, so the
readings of a plateau that sit on one code share that code's rounding error, within ±q/2,
through the same ∂output/∂T — bounded, and by the die's approach to its setpoint not
random (stats.BoundedShared).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.problem import LinearProblem
from calibration.temperature_lsb import MAX_LSB_C

MIN_PLATEAUS = 2  # one plateau has no between-plateau variance to speak of
# A quantised channel (temperature_grid): its codes are values recorded on at least
# GRID_CODE_READINGS readings of one plateau (a dithered capture mean rarely repeats
# exactly; a mean across a code change, two codes mixed, may twice); q, from the
# spacings between codes, at least GRID_MIN_TOL_RATIO recorded resolutions and GRID_MIN_C
# (below it the rounding's sd, under 0.006 °C, is nothing against a tempco; a dithered
# channel's capture means sit on a grid of q/n) and at most GRID_MAX_C (the coarsest channel
# read: a whole degree), the GRID_CANDIDATES largest spacings tried; the readings within
# GRID_TOL_LSB resolutions of its grid at least GRID_ON_FRACTION of all (by chance a
# continuous value is within it in at most 3/10 of cases, at the smallest q; a die that
# lingers at a code's edge mixes two codes in many captures); of the spacings between codes,
# at least GRID_MIN_FRACTION on it (on twice the LSB, half the adjacent codes are off); at
# least GRID_MIN_READINGS readings.
GRID_CODE_READINGS = 3
GRID_ON_FRACTION = 0.6
GRID_MIN_FRACTION = 0.8
GRID_MIN_TOL_RATIO = 10.0
GRID_TOL_LSB = 3.0
GRID_MIN_C, GRID_MAX_C = 0.02, 1.0
GRID_MIN_READINGS = 10
GRID_MAX_DECIMALS = 6
GRID_CANDIDATES = 64
# A plateau holds a code (admitted_lsb_c) where one value is recorded on more than half its
# readings: capture means across a code's edge repeat where two codes mix alike, but not on
# most of a plateau.
HELD_MAJORITY = 0.5


def plateau_groups(pb: LinearProblem) -> stats.SharedGroups | None:
    """The two shared components of ``pb``'s whitened entries, or None with < 2 plateaus."""
    steps = np.asarray(pb.ctx.steps)
    _, k = np.unique(steps, return_inverse=True)
    n_k = int(k.max()) + 1 if k.size else 0
    if n_k < MIN_PLATEAUS:
        return None
    step_e = k[pb.row]
    axis = np.maximum(pb.axis, 0)
    n_ax = int(axis.max()) + 1
    loads, groups, names = [np.asarray(pb.w, float).copy()], [step_e * n_ax + axis], \
        ["plateau x axis"]
    lt = temperature_loading(pb)
    if lt is not None:
        loads.append(lt)
        groups.append(step_e)
        names.append("plateau temperature")
    return stats.SharedGroups(loads, groups, names)


def cap_cells(pb: LinearProblem) -> tuple[np.ndarray, np.ndarray] | None:
    """(each reading's plateau (N,), ids from 0; each entry's axis (m,)), for the sign-flip
    null's reading cap at each plateau's own scatter (stats.reading_cap); None with < 2
    plateaus."""
    _, k = np.unique(np.asarray(pb.ctx.steps), return_inverse=True)
    k = np.asarray(k).ravel()
    if k.size == 0 or int(k.max()) + 1 < MIN_PLATEAUS:
        return None
    return k, np.asarray(pb.axis)


def temperature_loading(pb: LinearProblem) -> np.ndarray | None:
    """(m,) whitened ∂output/∂T of each entry (per °C of the reading's temperature error),
    from the base model's derivative; None where the base has no temperature dependence."""
    dT = np.asarray(pb.ctx.draw_dtemp_g_per_c, float)
    if not np.any(dT != 0):
        return None
    lt = np.asarray(pb.lift(dT[:, :, None]), float)[:, 0] * pb.w
    if not np.any(np.isfinite(lt) & (lt != 0)):
        return None
    return np.where(np.isfinite(lt), lt, 0.0)


@dataclass(frozen=True)
class ChannelGrid:
    """A recorded temperature that sits on a grid: the readings of a plateau (``on_grid``)
    are its most recorded value + ``code``·``q_c`` — a quantised channel that does not
    dither."""

    q_c: float  # the grid's spacing (the channel's LSB), °C
    code: np.ndarray  # (N,) int: the reading's code within its plateau (0 off the grid)
    on_grid: np.ndarray  # (N,) bool: the reading's value is a code
    fraction: float  # share of the readings on the grid


def _decimals(x: np.ndarray) -> int:
    """The fewest decimals that write every value of ``x`` (its recorded resolution)."""
    for d in range(GRID_MAX_DECIMALS + 1):
        y = x * 10.0**d
        if np.all(np.abs(y - np.round(y)) < 1e-6 * np.maximum(1.0, np.abs(y)) + 1e-9):
            return d
    return GRID_MAX_DECIMALS


def temperature_grid(temp_c: np.ndarray, steps: np.ndarray) -> ChannelGrid | None:
    """The grid a non-dithering quantised temperature channel puts its readings on, or None.

    Why (issue 22): a channel quantised to q whose own noise is far below q (a 0.1 °C chamber
    display, the ADXL355's ~0.11 °C temperature code, a 0.0625 °C part, each read as it is)
    records one code for every reading of a settled plateau, so all of them carry the same
    rounding error — shared by the plateau, which sign flips per reading cannot reproduce.
    A dithered channel's capture means fall between codes and rarely repeat.

    The codes are the values recorded :data:`GRID_CODE_READINGS` times within a plateau.
    Two codes within :data:`GRID_MAX_C` of each other differ by a multiple of q. Each such
    spacing is tried, the largest first; one that holds :data:`GRID_MIN_FRACTION` of those
    spacings is refitted by least squares to them, and the first whose grid through each
    plateau's most recorded code holds :data:`GRID_ON_FRACTION` of the readings is q (a
    repeated mean half-way between two codes suggests q/2, which holds them too: hence the
    largest). A grid per plateau, not one through all: a code written to fewer decimals
    than q has (0.0625 °C as 0.062) drifts off one grid across 100 °C. None when no two
    codes are that near (a channel whose codes are the setpoints alone: q not determined by
    the recording, :func:`one_code_per_plateau`), or no spacing of at least
    :data:`GRID_MIN_TOL_RATIO` recorded resolutions and :data:`GRID_MIN_C` holds the
    readings (a dithered or continuous channel).
    """
    t = np.asarray(temp_c, float)
    ok = np.isfinite(t)
    if int(ok.sum()) < GRID_MIN_READINGS:
        return None
    x, st = t[ok], np.asarray(steps)[ok]
    res = 10.0 ** -_decimals(x)
    tol = GRID_TOL_LSB * 0.51 * res
    codes: list[np.ndarray] = []
    top = np.empty(t.size)  # each reading's plateau's most recorded value
    for s_ in np.unique(st):
        u, c = np.unique(x[st == s_], return_counts=True)
        top[np.asarray(steps) == s_] = u[np.argmax(c)]
        codes.append(u[c >= GRID_CODE_READINGS])
    code = np.unique(np.concatenate(codes))
    pairs = [code[i + 1:np.searchsorted(code, v + GRID_MAX_C + res / 2, side="right")] - v
             for i, v in enumerate(code)]
    d = np.concatenate(pairs) if pairs else np.zeros(0)
    d = d[d >= max(GRID_MIN_TOL_RATIO * res, GRID_MIN_C) - res / 2]
    for q0 in np.unique(np.round(d / res) * res)[::-1][:GRID_CANDIDATES]:
        k = np.round(d / q0)
        held = (k >= 1) & (np.abs(d - k * q0) <= tol)
        if held.sum() < GRID_MIN_FRACTION * d.size:  # 2q: half the adjacent codes off it
            continue
        q = float(np.dot(d[held], k[held]) / np.dot(k[held], k[held]))
        idx = np.round((t - top) / q)
        on = ok & (np.abs(t - top - idx * q) <= tol)
        frac = float(on.sum()) / x.size
        if frac >= GRID_ON_FRACTION:
            return ChannelGrid(q, np.where(on, idx, 0).astype(np.int64), on, frac)
    return None


def one_code_per_plateau(temp_c: np.ndarray, steps: np.ndarray) -> bool:
    """True when the recorded temperature holds one value through each plateau (on at least
    :data:`GRID_MIN_FRACTION` of its readings, two plateaus or more of
    :data:`GRID_MIN_READINGS` readings each): a channel that does not dither, but whose LSB
    the recording does not show (no plateau moves by one code; :func:`temperature_grid`
    finds none), so each plateau's temperature is known only to half an unknown LSB."""
    t = np.asarray(temp_c, float)
    st = np.asarray(steps)
    seen = 0
    for s_ in np.unique(st):
        x = t[(st == s_) & np.isfinite(t)]
        if x.size < GRID_MIN_READINGS:
            continue
        if np.unique(x, return_counts=True)[1].max() < GRID_MIN_FRACTION * x.size:
            return False
        seen += 1
    return seen >= MIN_PLATEAUS


def held_code_resolution_c(temp_c: np.ndarray, steps: np.ndarray) -> float | None:
    """A lower bound of the LSB of a channel that holds one value through each plateau
    (:func:`one_code_per_plateau`) but shows no grid: the resolution its codes are written
    to, or None.

    Why (issue 22): such a channel does not show its LSB, yet its codes do. Codes written to
    d decimals, not all whole degrees, lie on a 10⁻ᵈ °C grid: a finer channel would put k
    plateaus' codes all on that grid with a chance near 10⁻ᵏ, so the channel rounds at least
    that coarsely (q ≥ 10⁻ᵈ; a value recorded as 25.1 is known to ±0.05 °C at best). Codes
    that are all whole degrees say nothing: a die settled on setpoints that lie on codes
    writes the setpoints, whatever the LSB (on the second generator, 52 of the 69 such
    recordings, a 0.1 °C channel; docs/benchmarks.md). The resolution of all the readings is
    no bound either: an approach plateau's capture means, written to 3 decimals, set it.
    """
    t = np.asarray(temp_c, float)
    st = np.asarray(steps)
    if not one_code_per_plateau(t, st):
        return None
    codes = []  # each plateau's most recorded value: its code, where the plateau holds one
    for s_ in np.unique(st):
        x = t[(st == s_) & np.isfinite(t)]
        if x.size:
            u, c = np.unique(x, return_counts=True)
            codes.append(u[np.argmax(c)])
    d = _decimals(np.asarray(codes))
    return None if d == 0 else 10.0**-d


def admitted_lsb_c(temp_c: np.ndarray, steps: np.ndarray) -> float | None:
    """The coarsest LSB a non-dithering channel's codes admit (at most :data:`GRID_MAX_C`),
    or None (a dithered or continuous channel: its readings are not codes).

    Why (issue 22): a channel that does not dither holds one code through a settled
    plateau: one value on more than :data:`HELD_MAJORITY` of the plateau's readings (and
    :data:`GRID_CODE_READINGS` or more). Where such plateaus hold :data:`GRID_ON_FRACTION`
    of the readings, on two plateaus or more, their held codes are the channel's. Codes
    written to d decimals could come from any channel whose LSB is 10⁻ᵈ °C or a multiple of
    it, up to a whole degree, so the recording admits an LSB of max(10⁻ᵈ, the grid's q,
    :func:`temperature_grid`) — a whole degree where every held code is one (a die settled on
    setpoints that lie on codes writes the setpoints whatever the LSB). The other readings
    narrow nothing: a plateau that does not hold one value (an approach, its capture means
    written to 3 decimals, some repeated where two codes mix alike) records means of codes,
    which a coarser channel writes too. Where no plateau holds a code, a grid's q. This is
    not the LSB but the coarsest one the recording cannot rule out; each plateau's
    temperature is known to ±Q/2 and no better, and a pattern of the channel within what
    that rounding can make is not told from it (within_rounding.py).
    """
    t = np.asarray(temp_c, float)
    st = np.asarray(steps)
    ok = np.isfinite(t)
    if int(ok.sum()) < GRID_MIN_READINGS:
        return None
    codes: list[float] = []
    on = 0
    for s_ in np.unique(st[ok]):
        u, c = np.unique(t[ok & (st == s_)], return_counts=True)
        i = int(np.argmax(c))
        if c[i] >= GRID_CODE_READINGS and c[i] > HELD_MAJORITY * c.sum():
            codes.append(float(u[i]))
            on += int(c.sum())
    grid = temperature_grid(t, st)
    held = len(codes) >= MIN_PLATEAUS and on >= GRID_ON_FRACTION * int(ok.sum())
    if not held:
        return None if grid is None else min(grid.q_c, GRID_MAX_C)
    q = 10.0 ** -_decimals(np.asarray(codes))
    if grid is not None:
        q = max(q, grid.q_c)
    return min(q, GRID_MAX_C)


# A lattice of means of codes is read only where its spacing is this many times the
# resolution the means are written to (finer, the writing's own rounding hides it) and a
# plateau holds this many distinct means on it.
LATTICE_MIN_SPACING_RES = 8.0
LATTICE_MIN_VALUES = 5


def mean_code_lsb_c(temp_c: np.ndarray, n_samples: np.ndarray | None,
                    steps: np.ndarray) -> float | None:
    """The LSB (°C) of a channel whose capture means are averages of ``n`` of its codes, read
    from the lattice of spacing LSB/n the means lie on; None where they do not.

    Why (issue 22): a channel quantised at q whose own noise is well below q does not dither,
    and each plateau's mean of its codes keeps a rounding error up to ±q/2, shared by the
    plateau (on the third generator's nulls, 30 of 47 false alarms: LSB 0.25–0.5 °C, noise
    below 0.4 LSB, docs/benchmarks.md). Such means are not on the code grid
    (:func:`temperature_grid`), but a mean of n codes is (k/n)·q plus the codes' offset: the
    distinct means of a plateau differ by multiples of q/n. Where every plateau's distinct
    means (≥ :data:`LATTICE_MIN_VALUES` of them) fit one such lattice to the resolution they
    are written to, q is the channel's LSB as surely as a declared one; a channel that is not
    quantised, or means written too coarsely, fit no lattice (the project's twin, the
    second generator's channels: none).

    A channel whose noise is so far below q that the settled plateaus hold one code each
    shows the lattice on one plateau only, the one whose die sits at a code's edge: there
    q is read where every other plateau holds one code (more than :data:`HELD_MAJORITY` of
    its readings, :data:`GRID_CODE_READINGS` or more), two plateaus or more, and those codes
    lie on the multiples of q to the resolution they are written to
    (:func:`_one_lattice_and_held_codes`; on the third generator's nulls a 0.5 °C channel of
    noise 0.03 LSB: four plateaus on one code each, one with seven means 0.5/304 °C apart).
    """
    if n_samples is None:
        return None
    t = np.asarray(temp_c, float)
    n = np.asarray(n_samples, float)
    st = np.asarray(steps)
    ok = np.isfinite(t) & np.isfinite(n) & (n > 1)
    if int(ok.sum()) < GRID_MIN_READINGS:
        return None
    res = 10.0 ** -_decimals(t[ok])
    q_found: list[float] = []
    for nv in np.unique(n[ok]):
        sel = ok & (n == nv)
        spacings = []
        for s_ in np.unique(st[sel]):
            x = np.unique(t[sel & (st == s_)])
            d = np.diff(x)
            d = d[d > res / 2]
            if x.size < LATTICE_MIN_VALUES or d.size == 0:
                continue
            s = float(np.min(d))  # the smallest step between two means: one lattice spacing
            if s < LATTICE_MIN_SPACING_RES * res:
                return None  # finer than the writing: not told from a continuous channel
            k = np.round((x - x[0]) / s)
            A = np.column_stack([np.ones_like(k), k])
            coef, *_ = np.linalg.lstsq(A, x, rcond=None)
            if np.max(np.abs(x - A @ coef)) > 1.01 * res:
                return None  # one plateau off the lattice: not means of codes
            spacings.append(float(coef[1]))
        if len(spacings) >= MIN_PLATEAUS:
            q_found.append(float(np.median(spacings)) * float(nv))
        elif len(spacings) == 1:
            q1 = _one_lattice_and_held_codes(t[sel], st[sel], spacings[0], float(nv), res)
            if q1 is not None:
                q_found.append(q1)
    if not q_found:
        return None
    q = max(q_found)
    return q if q <= MAX_LSB_C else None  # coarser is no temperature channel's LSB


def _one_lattice_and_held_codes(t: np.ndarray, st: np.ndarray, spacing: float, n: float,
                                res: float) -> float | None:
    """q = ``spacing``·``n`` where one plateau's means lie on a lattice of ``spacing`` and
    every other plateau holds one code, :data:`MIN_PLATEAUS` or more of them, their codes
    on the multiples of q to the written resolution (:func:`mean_code_lsb_c`); else None."""
    q = spacing * n
    held: list[float] = []
    for s_ in np.unique(st):
        u, c = np.unique(t[st == s_], return_counts=True)
        i = int(np.argmax(c))
        if c[i] >= GRID_CODE_READINGS and c[i] > HELD_MAJORITY * c.sum():
            held.append(float(u[i]))
        elif u.size < LATTICE_MIN_VALUES:
            return None  # a plateau neither on one code nor showing the lattice
    if len(held) < MIN_PLATEAUS or len(held) != np.unique(st).size - 1:
        return None
    d = np.asarray(held[1:]) - held[0]
    k = np.round(d / q)  # the lattice's q is known to ~res/spacing: refitted on the codes
    if not np.any(k != 0):
        return None  # one code on every plateau: q not shown by the codes
    q_codes = float(np.dot(d, k) / np.dot(k, k))
    if abs(q_codes - q) > 0.5 * q / np.max(np.abs(k)) or \
            np.max(np.abs(d - k * q_codes)) > 1.01 * res:
        return None  # held codes not q apart: not one channel quantised at q
    return q_codes


def rounding_box(pb: LinearProblem, q_c: float) -> stats.BoundedShared | None:
    """Any rounding error within ±``q_c``/2 per plateau and recorded value, through the
    base model's whitened ∂output/∂T (the groups of :func:`quantised_channel`); None where
    the base has no temperature dependence."""
    lt = temperature_loading(pb)
    if lt is None:
        return None
    return stats.BoundedShared(_value_groups(pb), lt, q_c / 2.0)


def _value_groups(pb: LinearProblem) -> np.ndarray:
    """(m,) the entries' groups: one per plateau and recorded temperature value."""
    ctx = pb.ctx
    t = np.asarray(ctx.temp_c, float)
    key = np.where(np.isfinite(t), t, np.arange(ctx.n) + 1e9)
    _, g_read = np.unique(np.column_stack([ctx.steps, key]), axis=0, return_inverse=True)
    return np.asarray(g_read).ravel()[pb.row]


@dataclass(frozen=True)
class QuantisedChannel:
    """A temperature channel quantised to ``q_c`` without dither, and what the null makes of
    its rounding error (:func:`quantised_channel`)."""

    q_c: float  # the channel's LSB, °C
    declared: bool  # q from the recording's own column (temperature_lsb), not its grid
    fraction: float  # share of the readings on the grid (1.0 when declared or a lower bound)
    lower_bound: bool  # q only the resolution its held codes are written to (no grid shown)
    known: tuple[stats.SharedGroups, np.ndarray]  # the scan's: a draw per group at q²/12
    bounded: stats.BoundedShared  # the families': any error within ±q/2 per group


def quantised_channel(pb: LinearProblem, declared_q_c: float | None = None,
                      by_plateau: bool = False) -> QuantisedChannel | None:
    """The rounding error of a non-dithering quantised temperature channel, or None (no LSB
    declared, no grid found and no held codes' resolution, or no temperature dependence).

    q: ``declared_q_c`` (the recording's ``<channel>_lsb_c`` column, temperature_lsb.py),
    else the grid the readings sit on (:func:`temperature_grid`), else, for a channel that
    holds one value per plateau, the resolution its codes are written to — a lower bound of
    q (:func:`held_code_resolution_c`), so the draw below is the least the rounding adds.
    The groups: the readings of one plateau that record the same value share one error (a
    settled plateau on one code is one group; a capture mean across a code change is its
    own, or shares it with an equal one); each error is code − die, within ±q/2, through
    the base model's whitened ∂output/∂T.

    Two uses. The families with columns (a channel step, a hysteresis, a rate or lag — each
    a pattern over many plateaus) take the bound (``bounded``, stats.linear_stats): a die
    that settles towards setpoints on codes has an error of the approach's sign on every
    plateau of a leg, a pattern a random draw per plateau does not make (issue 22: 11 of
    the 15 clean-channel nulls that fired). The scan's local blocks (one plateau, one
    position) take a draw per group at the uniform error's variance q²/12 (``known``):
    for one group's error a Gaussian of that variance has the heavier tail. Known, not
    fitted: an effect in the data does not raise it (docs/diagnosis.md §2).
    ``by_plateau``: one group per plateau, for a channel whose capture means average its
    codes (:func:`mean_code_lsb_c`): every mean is a value of its own, yet the rounding
    error is the settled die's against the codes, one per plateau.
    """
    ctx = pb.ctx
    if ctx.temperature_source == "none":
        return None
    grid = None if declared_q_c is not None else temperature_grid(ctx.temp_c, ctx.steps)
    held_q_c = None if declared_q_c is not None or grid is not None else \
        held_code_resolution_c(ctx.temp_c, ctx.steps)
    if declared_q_c is None and grid is None and held_q_c is None:
        return None
    lt = temperature_loading(pb)
    if lt is None:
        return None
    q = float(declared_q_c) if declared_q_c is not None else \
        grid.q_c if grid is not None else float(held_q_c)
    group = np.asarray(ctx.steps)[pb.row] if by_plateau else _value_groups(pb)
    sg = stats.SharedGroups([lt], [group], ["quantised temperature channel"])
    return QuantisedChannel(q, declared_q_c is not None,
                            1.0 if grid is None else grid.fraction, held_q_c is not None,
                            (sg, np.array([q**2 / 12.0])),
                            stats.BoundedShared(group, lt, q / 2.0))
