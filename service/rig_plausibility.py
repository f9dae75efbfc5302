"""Physical plausibility of a chamber seen through its register map (``soakcal rig check``).

A map can be syntactically perfect and still read the chamber wrong: a
controller set to whole degrees read with ``scale = 10`` shows 2.3 °C for
23 °C, and every setpoint written through it lands ten times too far. The
controller cannot tell; physics can. The sensors' dies sit in the chamber's air,
so at rest they read what the PV should read, within a few °C
(:data:`DIE_PV_TOLERANCE_C`); and a commanded ramp must show up as the working
setpoint moving at that rate. When they disagree this module names the likely
cause — a scale factor, °F or kelvin, swapped words, per-hour ramp units, a
controller in manual — and the map key (or controller setting) that fixes it.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drivers.faults import ModbusExceptionReply, ValueOutOfRange

if TYPE_CHECKING:
    from drivers.clock import Clock
    from service.rig_check import _Recorder

#: Sensor die vs chamber PV at rest, °C: package self-heating, the uncalibrated die
#: sensor's offset and a little lag fit in this; a ×10, ×0.1, °F or K error does not.
DIE_PV_TOLERANCE_C = 5.0
#: How closely a misreading must turn the die's temperature into the PV to be named as
#: the cause: tighter than the agreement band, so a cause is named only when it fits well.
CAUSE_TOLERANCE_C = 2.5
NUDGE_C = 0.5  # setpoint nudge, °C: visible at 0.1 °C resolution, harmless to any soak
RAMP_CHECK_C_PER_MIN = 1.0  # commanded during the nudge; the WSP must move at this rate
RAMP_POLL_S = 2.0
RAMP_RATIO_OK = (0.5, 2.0)  # observed / commanded WSP rate accepted as "the same"
RAMP_FACTOR_TOLERANCE = 0.2  # a ratio this close to ×10, ×0.1 or ×60 is blamed on the map
SETPOINT_TOLERANCE_C = 0.051  # read-back of a written setpoint at 0.1 °C resolution
#: Without a working setpoint the PV must follow the nudge PV_FOLLOW_C towards it, then
#: come back PV_RETURN_C once the setpoint is restored (less: it can only come back as far as
#: the old setpoint), each within PV_FOLLOW_MAX_S (the air's lag: minutes on a real chamber),
#: from a chamber settled within PV_SETTLED_C: steps of 0.1 °C readings, far above a settled
#: PV's noise.
PV_FOLLOW_C = 0.3
PV_RETURN_C = 0.2
PV_FOLLOW_MAX_S = 240.0
PV_SETTLED_C = 0.3
#: Registers whose scale is the controller's decimal point, like the PV's.
TEMPERATURE_REGISTERS = ("process_c", "setpoint_c", "working_setpoint_c", "ramp_c_per_min")


def usable_range_c(chamber: Any, rig: dict[str, Any]) -> tuple[float, float]:
    """The map's range narrowed by the rig config's ``range_c``."""
    lo, hi = chamber.range_c
    cfg_range = (rig.get("chamber") or {}).get("range_c")
    if cfg_range:
        lo, hi = max(lo, float(cfg_range[0])), min(hi, float(cfg_range[1]))
    return lo, hi


def map_file(regmap: Any) -> str:
    """The map's file name as a lab knows it (``eurotherm-3216.toml``)."""
    return Path(regmap.source).name if regmap.source else f"map {regmap.name}"


async def silent_registers(chamber: Any) -> list[tuple[str, str]]:
    """Each status register the controller refuses, as (detail, fix): the map names
    an address this model does not have (or has under another number)."""
    regmap = getattr(chamber, "regmap", None)
    if regmap is None:
        return []
    out: list[tuple[str, str]] = []
    roles = ("process_c", "setpoint_c", "working_setpoint_c", "ramp_c_per_min", "run", "alarms")
    for name in roles:
        f = getattr(regmap, name, None)
        if f is None:
            continue
        try:
            await chamber.link.read_field(f)
        except ModbusExceptionReply as exc:
            out.append((f"register `{name}` (address {f.address}) does not answer: "
                        f"exception code {exc.code}",
                        f"the controller has no register {f.address}: correct `address` of "
                        f"register `{name}` in {map_file(regmap)} from the manual, or remove "
                        "it if this model lacks it"))
    return out


async def check_mode(rec: _Recorder, chamber: Any) -> bool:
    """A controller in manual holds its output: it would not follow any setpoint."""
    read_info = getattr(chamber, "read_info_bits", None)
    if read_info is None or not chamber.regmap.info_bits:
        return True
    info = await read_info()
    if "manual_mode" in info:
        return rec.add("chamber", "mode", "fail",
                       "the controller reports manual mode: it holds its output and does not "
                       "follow the setpoint",
                       "switch the controller to automatic (Auto/Manual at its front panel)")
    return rec.add("chamber", "mode", "pass", "automatic (not in manual)")


async def check_pv_against_die(rec: _Recorder, chamber: Any, dies_c: list[float]) -> bool:
    """The chamber's PV against the mean die temperature of the rig's sensors."""
    if not dies_c:
        return rec.add("chamber", "pv_vs_die", "skip",
                       "no sensor die temperature to compare the PV with (sensor check failed)")
    st = await chamber.read_status()
    pv, die = st.process_c, sum(dies_c) / len(dies_c)
    seen = f"PV reads {_temp(pv)} °C while the die reads {die:.1f} °C"
    if _is_reading(pv) and abs(pv - die) <= DIE_PV_TOLERANCE_C:
        if 0.9 * abs(die) <= DIE_PV_TOLERANCE_C:
            return rec.add("chamber", "pv_vs_die", "skip",
                           f"{seen}: they agree, but this near 0 °C a ×0.1 scale error would "
                           "agree too", "rerun the check with the chamber nearer room temperature")
        return rec.add("chamber", "pv_vs_die", "pass",
                       f"PV {pv:.1f} °C, die {die:.1f} °C: within {DIE_PV_TOLERANCE_C:g} °C")
    regmap = getattr(chamber, "regmap", None)
    if regmap is None:
        return rec.add("chamber", "pv_vs_die", "fail", seen,
                       "check the chamber driver's units and scale")
    cause, fix = await _likely_cause(chamber, regmap, pv, die)
    if cause is None:
        # Without a working-setpoint register, the PV's distance from SP says "still moving".
        moving_c = st.working_setpoint_c if st.working_setpoint_c is not None else st.process_c
        unsettled = abs(moving_c - st.setpoint_c) > (0.1 if st.working_setpoint_c is not None
                                                     else DIE_PV_TOLERANCE_C)
        return rec.add("chamber", "pv_vs_die", "fail",
                       f"{seen}: no scale, unit or word-order error explains it"
                       + ("; the chamber is still ramping, so the die may lag" if unsettled
                          else ""),
                       f"check `address` of register `process_c` in {map_file(regmap)} against "
                       "the manual (the control loop's PV, not a spare input), and that the "
                       "sensor is inside this chamber")
    return rec.add("chamber", "pv_vs_die", "fail", f"{seen}: {cause}", fix)


def _fc16_hint(regmap: Any) -> str:
    """A written setpoint that reads back unchanged may be a write the controller
    acknowledged and ignored: some accept only single-register writes (FC 6) outside
    their program area (CSZ EZT-430i manual §4.9)."""
    f = getattr(regmap, "setpoint_c", None)
    if f is None or f.single_write or f.n_registers != 1 or f.table != "holding":
        return ""
    return (f"; or the controller ignores multi-register writes (FC 16): set "
            f"`write = \"single\"` on register `setpoint_c` in {map_file(regmap)}")


def _is_reading(value_c: float) -> bool:
    """A temperature a sensor can report: finite, and not a float's debris (1e-40 °C is
    what two swapped words of a float often decode to, not a temperature near 0 °C)."""
    return math.isfinite(value_c) and (value_c == 0.0 or 1e-6 < abs(value_c) < 1e6)


def _temp(value_c: float) -> str:
    """A reading as a person reads it: one decimal, or 3 digits when absurd."""
    return f"{value_c:.1f}" if value_c == 0.0 or 0.05 <= abs(value_c) < 1e5 \
        else f"{value_c:.3g}"


async def _likely_cause(chamber: Any, regmap: Any, pv: float,
                        die: float) -> tuple[str | None, str]:
    """The misreading that turns the die's temperature into this PV, best match first."""
    f = regmap.process_c
    file = map_file(regmap)
    words = await chamber.link.read_registers(f.address, f.n_registers)
    if not any(words):
        return ("the register reads all bits 0, as an address with nothing behind it does",
                f"check `address` of register `process_c` in {file} against the manual "
                "(the control loop's PV)")
    temps = [n for n in TEMPERATURE_REGISTERS[1:]
             if getattr(regmap, n) is not None and getattr(regmap, n).scale == f.scale]
    also = f" (and {', '.join(temps)}, which share its decimal point)" if temps else ""
    candidates: list[tuple[float, str, str]] = []
    for k in (10.0, 100.0, 0.1, 0.01):
        if not math.isfinite(pv):
            break
        # The map reads 1/k of the truth: its scale (counts per °C) is k times too large.
        candidates.append((pv * k, f"×{k:g} — the map's scale does not match the "
                           "controller's decimal point",
                           f"set `scale = {f.scale:g}`→`{f.scale / k:g}` for register "
                           f"`process_c`{also} in {file}, or set the controller's decimal "
                           "point to match the map"))
    if math.isfinite(pv):
        # The other temperature registers this map has (a WSP may be absent).
        others = " and ".join(n for n in ("setpoint_c", "working_setpoint_c")
                              if getattr(regmap, n, None) is not None)
        candidates.append(((pv - 32.0) / 1.8, "the controller reads in °F",
                           f"set the controller's temperature units to °C, or map °F in {file}: "
                           f"register `process_c` `scale = {f.scale * 1.8:g}`, "
                           f"`offset = -17.7778`, likewise {others}"))
        candidates.append((pv - 273.15, "the controller reads in kelvin",
                           f"set the controller's units to °C, or give register `process_c` "
                           f"(and {others}) `offset = -273.15` in {file}"))
    if f.n_registers == 2:
        other = "low_first" if f.word_order == "high_first" else "high_first"
        swapped = replace(f, word_order=other).decode(words)
        candidates.append((swapped, "the two 16-bit words of the 32-bit value are swapped",
                           f"set `word_order = \"{other}\"` (now \"{f.word_order}\") in "
                           f"[defaults] of {file}, or on register `process_c` alone"))
    fits = sorted((abs(t - die), why, fix) for t, why, fix in candidates
                  if math.isfinite(t) and abs(t - die) <= CAUSE_TOLERANCE_C)
    if not fits:
        return None, ""
    _, why, fix = fits[0]
    if len(fits) > 1:  # two readings explain it: say both rather than guess
        return f"{why}, or else {fits[1][1]}", f"{fix}; or else: {fits[1][2]}"
    return why, fix


async def nudge_and_ramp(rec: _Recorder, chamber: Any, rig: dict[str, Any],
                         clock: Clock) -> bool:
    """Nudge SP by :data:`NUDGE_C` at :data:`RAMP_CHECK_C_PER_MIN`, watch WSP move, put back.

    The written setpoint must read back; while the chamber runs, the working setpoint
    must move at the commanded rate (a per-hour ramp moves 60× slower, a controller in
    manual not at all). Takes about ``NUDGE_C / rate`` of rig time (30 s).
    """
    st0 = await chamber.read_status()
    sp0, ramp0 = st0.setpoint_c, st0.ramp_c_per_min
    lo, hi = usable_range_c(chamber, rig)
    target = sp0 + NUDGE_C if sp0 + NUDGE_C <= hi else sp0 - NUDGE_C
    regmap = getattr(chamber, "regmap", None)
    limit = getattr(regmap, "max_ramp_c_per_min", None)
    rate = min(RAMP_CHECK_C_PER_MIN, limit) if limit else RAMP_CHECK_C_PER_MIN
    # Optional roles: a controller without a static ramp steps (nothing to command), one
    # without a working setpoint has nothing to time the ramp on.
    ramps = (bool(getattr(chamber, "has_static_ramp", True)) if regmap is None
             else regmap.ramp_field() is not None)
    timed = ramps and st0.working_setpoint_c is not None
    watch: tuple[list[tuple[float, float]], float] | None = None
    # Nothing to time: the PV itself must follow the nudge there and back (a chamber in
    # standby drifts one way, a profile-owned setpoint does not move it at all).
    follow = st0.running and not timed and abs(st0.process_c - sp0) <= PV_SETTLED_C
    legs: list[tuple[float, float]] = []
    sign = 1.0 if target > sp0 else -1.0
    if st0.running and timed:
        await chamber.set_ramp_rate(rate)
    try:
        await chamber.set_setpoint(target)
        t0 = clock.now()
        first = await chamber.read_status()
        got = first.setpoint_c
        if st0.running and timed and first.working_setpoint_c is not None:
            watch = await _watch_wsp(chamber, clock, target, rate, t0,
                                     first.working_setpoint_c)
        if follow:
            legs.append(await _watch_pv(chamber, clock, sign, first.process_c, PV_FOLLOW_C))
    finally:
        await chamber.set_setpoint(sp0)
        if st0.running and timed:
            await _restore_ramp(chamber, ramp0)
    if legs and _moved(legs[0][0], PV_FOLLOW_C):
        legs.append(await _watch_pv(chamber, clock, -sign,
                                    (await chamber.read_status()).process_c, PV_RETURN_C))
    back = (await chamber.read_status()).setpoint_c
    if abs(got - target) > SETPOINT_TOLERANCE_C or abs(back - sp0) > SETPOINT_TOLERANCE_C:
        return rec.add("chamber", "setpoint_nudge", "fail",
                       f"wrote {target:.2f} °C, read {got:.2f} °C; restored {sp0:.2f} °C, "
                       f"read {back:.2f} °C",
                       "the setpoint register is read-only, remote setpoint is disabled, "
                       "or the map's scale/word order is wrong" + _fc16_hint(regmap))
    nudged = f"SP {sp0:.1f} → {target:.1f} → {back:.1f} °C"
    if watch is None:
        rec.add("chamber", "setpoint_nudge", "pass", nudged)
        file = map_file(regmap) if regmap is not None else "the map"
        if not ramps and regmap is None:
            why = ("the controller has no ramp to command (it steps to each setpoint at the "
                   "chamber's own rate): there is no commanded ramp to time")
        elif not ramps:
            why = (f"{file} lists ramp_c_per_min under absent_roles: the controller steps to "
                   "each setpoint, there is no commanded ramp to time")
        elif not timed:
            why = (f"{file} has no working-setpoint register (absent_roles): the ramp cannot "
                   "be timed here; a campaign judges arrival on the PV")
        else:
            why = "the chamber is stopped: the ramp is watched only while it runs"
        rec.add("chamber", "ramp", "skip", why)
        if st0.running and not timed:
            return _judge_follow(rec, legs, st0.process_c, sp0, target)
        return True
    rec.add("chamber", "setpoint_nudge", "pass", nudged)
    samples, _ = watch
    return await _judge_ramp(rec, chamber, samples, target, rate)


async def _watch_pv(chamber: Any, clock: Clock, sign: float, pv0: float,
                    enough_c: float) -> tuple[float, float]:
    """(°C the PV moved in direction ``sign`` from ``pv0``, seconds): polled until it
    moved ``enough_c`` or :data:`PV_FOLLOW_MAX_S` passed."""
    t0, moved = clock.now(), 0.0
    while clock.now() - t0 < PV_FOLLOW_MAX_S:
        await clock.sleep(RAMP_POLL_S)
        moved = ((await chamber.read_status()).process_c - pv0) * sign
        if _moved(moved, enough_c):
            break
    return moved, clock.now() - t0


def _moved(moved_c: float, enough_c: float) -> bool:
    """Moved far enough: readings of 0.1 °C resolution differ by 0.19999... for 0.2."""
    return moved_c >= enough_c - 1e-6


def _judge_follow(rec: _Recorder, legs: list[tuple[float, float]], pv0: float, sp0: float,
                  target: float) -> bool:
    """Without a working setpoint, the PV following the nudge there and back is the only
    sign that the controller controls at the setpoint it was given."""
    if not legs:
        return rec.add("chamber", "pv_follows", "skip",
                       f"the chamber is not settled (PV {pv0:.1f} °C, SP {sp0:.1f} °C): the PV "
                       "is watched following the nudge only from a settled chamber",
                       "rerun the check once the chamber has settled at its setpoint")
    (up, t_up), *rest = legs
    there = f"{target:.1f} °C"
    if not _moved(up, PV_FOLLOW_C):
        return rec.add("chamber", "pv_follows", "fail",
                       f"the PV moved {up:+.2f} °C toward the nudged setpoint {there} in "
                       f"{t_up:.0f} s (needed {PV_FOLLOW_C:g} °C): the controller does not "
                       "follow the setpoint it was given",
                       "check at the controller that it is controlling (not in standby or "
                       "manual) and that no running program or profile owns its setpoint (a "
                       "map may need a [[sequence.set_setpoint]], docs/registers.md)")
    down, t_down = rest[0]
    detail = (f"the PV moved {up:+.2f} °C toward {there} in {t_up:.0f} s, then "
              f"{down:+.2f} °C back toward {sp0:.1f} °C in {t_down:.0f} s")
    if not _moved(down, PV_RETURN_C):
        return rec.add("chamber", "pv_follows", "fail",
                       f"{detail} (needed {PV_RETURN_C:g} °C back): it went on one way, as a "
                       "chamber drifting in standby does",
                       "check at the controller that it is controlling (not in standby)")
    return rec.add("chamber", "pv_follows", "pass", detail)


async def _watch_wsp(chamber: Any, clock: Clock, target: float, rate: float, t0: float,
                     w0: float) -> tuple[list[tuple[float, float]], float]:
    """(time, WSP) samples until WSP reaches ``target`` or 1.5× the expected time passes."""
    expected_s = abs(target - w0) / rate * 60.0
    samples = [(t0, w0)]
    while clock.now() - t0 < 1.5 * expected_s + RAMP_POLL_S:
        if abs(samples[-1][1] - target) <= SETPOINT_TOLERANCE_C:
            break
        await clock.sleep(RAMP_POLL_S)
        wsp = (await chamber.read_status()).working_setpoint_c
        samples.append((clock.now(), samples[-1][1] if wsp is None else wsp))
    return samples, expected_s


async def _judge_ramp(rec: _Recorder, chamber: Any, samples: list[tuple[float, float]],
                      target: float, rate: float) -> bool:
    (t_a, w_a), (t_b, w_b) = samples[0], samples[-1]
    moved = abs(w_b - w_a)
    if len(samples) == 1:
        return rec.add("chamber", "ramp", "fail",
                       f"WSP jumped to {target:.1f} °C at once; commanded {rate:g} °C/min",
                       "the ramp rate is not applied: check register `ramp_c_per_min` and that "
                       "the controller's ramp (setpoint rate limit) is enabled")
    observed = moved / (t_b - t_a) * 60.0
    ratio = observed / rate
    detail = (f"WSP moved {moved:.2f} °C in {t_b - t_a:.0f} s: {observed:.2f} °C/min, "
              f"commanded {rate:g} °C/min")
    if RAMP_RATIO_OK[0] <= ratio <= RAMP_RATIO_OK[1]:
        return rec.add("chamber", "ramp", "pass", detail)
    regmap = chamber.regmap
    file = map_file(regmap)
    f = regmap.ramp_field()
    if ratio < 0.1:
        info = await chamber.read_info_bits() if hasattr(chamber, "read_info_bits") else ()
        if "manual_mode" in info:
            return rec.add("chamber", "ramp", "fail",
                           f"{detail}: the controller is in manual and holds its output",
                           "switch the controller to automatic")
        return rec.add("chamber", "ramp", "fail",
                       f"{detail}: {_slower(ratio)} — the controller's ramp units are likely "
                       "per hour (60× slower), or it is in manual/standby",
                       f"set the controller's ramp units to per minute, or set `scale = "
                       f"{f.scale:g}`→`{f.scale * 60:g}` for register `ramp_c_per_min` in {file}")
    cause, fix = _ramp_cause(ratio, f.scale, file)
    return rec.add("chamber", "ramp", "fail", f"{detail}: {ratio:.2g}× the commanded rate; "
                   f"{cause}", fix)


def _ramp_cause(ratio: float, scale: float, file: str) -> tuple[str, str]:
    """The likely cause of a working setpoint moving ``ratio`` × the commanded rate.

    Only a ratio that a map mistake explains (a power of ten: decimal places; 60: per
    second against per minute) is blamed on the map; any other is most often a clock that
    does not run at the speed the rig config says (a simulator or a sped-up twin).
    """
    for factor in (10.0, 100.0, 0.1, 0.01, 60.0):
        if abs(ratio / factor - 1.0) <= RAMP_FACTOR_TOLERANCE:
            return (f"the ramp register's scale is likely off by ×{factor:g}",
                    f"set `scale = {scale:g}`→`{scale / factor:.3g}` for register "
                    f"`ramp_c_per_min` in {file}, or check the controller's ramp units")
    return ("no scale or unit mistake gives that ratio",
            "if the rig runs on a sped-up clock (a simulator), set the rig config's "
            f"`time_scale` to its speed-up; otherwise check register `ramp_c_per_min` in {file} "
            "and the controller's ramp units")


def _slower(ratio: float) -> str:
    """How much slower than commanded, as far as the reading's resolution tells."""
    return f"{1 / ratio:.0f}× slower" if ratio > 0 else "not moving within the reading's resolution"


async def _restore_ramp(chamber: Any, ramp0: float) -> None:
    """The ramp as it was, even when it was above the map's limit (we did not set it).
    A rate that was never read (a sequence-written ramp before its first write) is left."""
    if not math.isfinite(ramp0):
        return
    try:
        await chamber.set_ramp_rate(ramp0)
    except ValueOutOfRange:
        await chamber.link.write_field(chamber.regmap.ramp_field(), ramp0)
