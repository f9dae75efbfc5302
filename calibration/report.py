"""Reports of a thermal calibration: the seed's Table 6 as text/JSON, and PNG figures.

* :func:`format_table6` -- per step: temperature, RMSE before, polynomial RMSE,
  measurement RMSE (Eq. 9, mg), as the seed's Table 6, under a header with the
  mode, method, positions and the temperature source and its conditioning.
* :func:`report_dict` -- the same as a JSON-able dict (``soakcal calibrate --json``).
* :func:`add_sections` -- adds the fitted coefficients (per step with σ, and
  the polynomial coefficients with σ) and, for reference recordings, the
  seed's Table 5 (tilt before/after, Eq. 10, SEOQ) to the report, so the text
  and the JSON show them.
* :func:`write_figures` -- |g| error before/after per reading, each parameter
  against temperature with its polynomial (Fig. 10), drift before/after (Fig. 11).
* :func:`plot_rmse_vs_positions` -- the seed's Fig. 8 (RMSE vs number of positions).
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: the service and CI have no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from calibration import metrics, schedules, sfem  # noqa: E402
from calibration.fit import fit_norm, fit_reference, rmse_norm_ug  # noqa: E402
from calibration.recording import Recording  # noqa: E402
from calibration.thermal import ThermalFit  # noqa: E402

# Display scaling per parameter group: (factor, unit, offset) for value → plotted.
_DISPLAY = {
    "g": (1e3, "mg", 0.0),  # bias
    "1": (1e6, "ppm", 1.0),  # scale factor: deviation from 1
    "rad": (1e3, "mrad", 0.0),
}


# Table 5 rows: positions whose reference z axis is within this of vertical (the
# seed's tilts are 0..30 deg; Eq. 10's roll atan(X/−Z) is meaningless near Z = 0).
TILT_MAX_DEG = 45.0


def add_sections(fit: ThermalFit, recording: Recording | None = None) -> None:
    """Put ``coefficients`` and (reference recordings) ``tilt_table`` into ``fit.report``."""
    fit.report["coefficients"] = coefficients_dict(fit)
    if recording is not None and recording.has_reference:
        fit.report["tilt_table"] = tilt_section(fit, recording)


def coefficients_dict(fit: ThermalFit) -> dict[str, Any]:
    """Per-step SFEM parameters with σ (Eq. 1) and the polynomial coefficients with σ (Eq. 8).

    Units as in the model file: bias g, scale 1, angles rad; physical
    coefficients in powers of (T − centre_c) (unit/°C^j).
    """
    m = fit.model
    names = sfem.PARAM_NAMES
    d = m.degree
    se = m.coeff_stderr if m.coeff_stderr is not None else np.full_like(m.coeffs, np.nan)
    powers = m.t_scale_c ** np.arange(d + 1)[None, :]
    return {
        "parameter_units": dict(zip(names, sfem.PARAM_UNITS, strict=True)),
        "steps": [
            {"step": st.step, "temperature_c": _num(st.temperature_c),
             "params": {n: _num(v) for n, v in zip(names, st.params, strict=True)},
             "stderr": {n: _num(v) for n, v in zip(names, st.stderr, strict=True)}}
            for st in m.steps
        ],
        "polynomial": {
            "degree": d,
            "centre_c": m.t_centre_c,
            "scale_c": m.t_scale_c,
            "physical_basis": "p(T) = sum_j physical[j] * (T - centre_c)**j",
            "physical": {n: [_num(v) for v in m.physical_coeffs()[k]]
                         for k, n in enumerate(names)},
            "physical_stderr": {n: [_num(v) for v in (se / powers)[k]]
                                for k, n in enumerate(names)},
        },
    }


def tilt_section(fit: ThermalFit, rec: Recording) -> dict[str, Any]:
    """The seed's Table 5 at the step nearest 25 °C, and tilt error RMS over every step.

    Angles by Eq. 10 from the reference (reference angle), the raw reading
    (without calibration) and the compensated reading (after calibration);
    SEOQ = |angle before − angle after| / 30° · 100 % (``metrics.seoq_percent``).
    """
    used = np.flatnonzero(fit.row_step >= 0)
    ref = rec.ref_g[used]  # type: ignore[index]
    raw = rec.raw_g[used]
    cal = fit.model.compensate(raw, fit.row_temperature_c[used], extrapolate=True)
    zfrac = np.abs(ref[:, 2]) / np.linalg.norm(ref, axis=1)
    level = zfrac >= np.cos(np.radians(TILT_MAX_DEG))
    out: dict[str, Any] = {"max_tilt_deg": TILT_MAX_DEG, "seoq_max_angle_deg":
                           metrics.SEOQ_MAX_ANGLE_DEG}
    if not level.any():
        out.update(step=None, rows=[], note=f"no position within {TILT_MAX_DEG:g}° of level "
                   "(z vertical): Eq. 10 tilt angles are not meaningful for these positions")
        return out
    rows_all = metrics.tilt_table(raw[level], cal[level], ref[level])
    err_b = np.array([r["err_raw_deg"] for r in rows_all])
    err_a = np.array([r["err_cal_deg"] for r in rows_all])
    steps = fit.row_step[used][level]
    temps = {st.step: st.temperature_c for st in fit.steps}
    finite = [s for s in np.unique(steps) if math.isfinite(temps.get(int(s), math.nan))]
    pick = min(finite, key=lambda s: abs(temps[int(s)] - 25.0)) if finite else int(steps[0])
    sel = steps == pick
    rows = [r for r, k in zip(rows_all, sel, strict=True) if k]
    out.update(
        step=int(pick), temperature_c=_num(temps.get(int(pick), math.nan)),
        rows=[{k: round(v, 4) for k, v in r.items()} for r in rows],
        rms_err_raw_deg=round(float(np.sqrt(np.mean(err_b**2))), 5),
        rms_err_cal_deg=round(float(np.sqrt(np.mean(err_a**2))), 5),
        positions_all_steps=int(level.sum()),
    )
    return out


def format_coefficients(fit: ThermalFit) -> str:
    """Text: per-step parameters ± σ, then the polynomial (physical) coefficients ± σ."""
    sec = fit.report.get("coefficients") or coefficients_dict(fit)
    names = sfem.PARAM_NAMES
    shown = [_DISPLAY[u] for u in sfem.PARAM_UNITS]
    heads = [f"{n}{' −1' if off else ''} ({unit})" for n, (_, unit, off) in zip(names, shown,
                                                                              strict=True)]
    w = 13
    lines = ["fitted SFEM parameters per step (Eq. 1), value and ±1σ "
             "(bias mg, scale factor − 1 in ppm, angles mrad):",
             f"{'step':>4} {'T (°C)':>8} " + " ".join(h.rjust(w) for h in heads)]
    for st in sec["steps"]:
        T = st["temperature_c"]
        vals, sds = [], []
        for k, (n, (f, _, off)) in enumerate(zip(names, shown, strict=True)):
            v, e = st["params"][n], st["stderr"][n]
            if not fit.model.identifiable[k]:  # held at its nominal value, not fitted
                vals.append("not fitted")
                sds.append("")
                continue
            vals.append("n/a" if v is None else _f((v - off) * f, ".4f"))
            sds.append("" if e is None else f"±{e * f:.4f}")
        lines.append(f"{st['step']:>4} {'n/a' if T is None else f'{T:.2f}':>8} "
                     + " ".join(v.rjust(w) for v in vals))
        lines.append(" " * 14 + " ".join(v.rjust(w) for v in sds))
    poly = sec["polynomial"]
    d = poly["degree"]
    lines.append("")
    lines.append(f"polynomial coefficients (Eq. 8), p(T) = Σ c_j (T − {poly['centre_c']:.3f} °C)^j,"
                 " value ± 1σ, in the parameter's unit (g, 1, rad) per °C^j:")
    lines.append(f"{'param':>6} " + " ".join(f"c{j}".rjust(24) for j in range(d + 1)))
    for k, n in enumerate(names):
        if not fit.model.identifiable[k]:
            lines.append(f"{n:>6}   not identifiable (held at {poly['physical'][n][0]:g})")
            continue
        cells = []
        for v, e in zip(poly["physical"][n], poly["physical_stderr"][n], strict=True):
            cells.append(f"{v:+.5e}" + ("" if e is None else f" ±{e:.1e}"))
        lines.append(f"{n:>6} " + " ".join(c.rjust(24) for c in cells))
    return "\n".join(lines)


def format_tilt_table(fit: ThermalFit) -> str | None:
    """The seed's Table 5 as text (None when the report has no tilt section)."""
    sec = fit.report.get("tilt_table")
    if not sec:
        return None
    if not sec["rows"]:
        return f"tilt (Table 5): {sec['note']}"
    temp = "temperature n/a" if sec["temperature_c"] is None else f"{sec['temperature_c']:.2f} °C"
    lines = [
        f"tilt angles (Table 5, Eq. 10) at step {sec['step']} ({temp}), "
        f"positions within {sec['max_tilt_deg']:g}° of level; SEOQ = |before − after| / "
        f"{sec['seoq_max_angle_deg']:g}° · 100 %",
        f"{'reference φ; θ (deg)':>22} {'without calibration':>22} {'after calibration':>22} "
        f"{'SEOQ φ; θ (%)':>16}",
    ]
    for r in sec["rows"]:
        lines.append(
            f"{_f(r['ref_pitch_deg'], '>10.3f')}; {_f(r['ref_roll_deg'], '<10.3f')}"
            f"{_f(r['raw_pitch_deg'], '>11.3f')}; {_f(r['raw_roll_deg'], '<10.3f')}"
            f"{_f(r['cal_pitch_deg'], '>11.3f')}; {_f(r['cal_roll_deg'], '<10.3f')}"
            f"{r['seoq_pitch_pct']:>8.2f}; {r['seoq_roll_pct']:<6.2f}")
    lines.append(f"tilt error RMS over {sec['positions_all_steps']} near-level readings of every "
                 f"step: {sec['rms_err_raw_deg']:.4f}° without calibration, "
                 f"{sec['rms_err_cal_deg']:.5f}° after")
    return "\n".join(lines)


def _f(v: float, spec: str) -> str:
    """``format(v, spec)`` without a minus sign on a value that rounds to zero ("-0.000")."""
    text = format(v, spec)
    return format(0.0, spec) if "-" in text and not any(c in "123456789" for c in text) \
        else text


def _num(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def report_dict(fit: ThermalFit) -> dict[str, Any]:
    """JSON-able report (a deep copy of ``fit.report``): header facts, Table 6 rows, drift."""
    return copy.deepcopy(fit.report)


def format_table6(fit: ThermalFit) -> str:
    """Text table like the seed's Table 6 with a header naming how it was obtained."""
    r = fit.report
    m = fit.model
    n_free = int(m.identifiable.sum())
    lines = [
        f"soakcal calibration of {r['recording']} ({r['rows']} rows)",
        f"mode: {m.mode} ({n_free} of 12 SFEM parameters identifiable), method: {m.method}, "
        f"polynomial degree {m.degree}, positions per step: {r['positions_per_step']}",
        f"temperature: {m.temperature_conditioning}",
    ]
    if m.valid_c is not None:
        lines.append(f"valid range: {m.valid_c[0]:.2f} .. {m.valid_c[1]:.2f} °C")
    lines.append("fitted: " + (", ".join(m.fitted) or "none"))
    if m.held:
        lines.append("held: " + "; ".join(f"{n} ({why})" for n, why in m.held.items()))
    for note in fit.notes:
        if not note.startswith("temperature conditioning"):
            lines.append(f"note: {note}")
    lines.append("")
    head = ("Step", "Temperature", "Before calibration", "Polynomial", "Measurement")
    units = ("", "(°C)", "RMSE (mg)", "RMSE (mg)", "RMSE (mg)")
    widths = (4, 11, 18, 10, 11)
    lines.append("  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True)))
    lines.append("  ".join(u.rjust(w) for u, w in zip(units, widths, strict=True)))
    for st in fit.steps:
        temp = "n/a" if not math.isfinite(st.temperature_c) else f"{st.temperature_c:.2f}"
        cells = (
            str(st.step), temp, f"{st.rmse_before_ug / 1e3:.2f}",
            f"{st.rmse_polynomial_ug / 1e3:.4f}", f"{st.rmse_measurement_ug / 1e3:.4f}",
        )
        lines.append("  ".join(c.rjust(w) for c, w in zip(cells, widths, strict=True)))
    drift = r.get("drift")
    if drift:
        b, a = drift["before"], drift["after"]
        lines.append("")
        lines.append(
            "drift at fixed orientation (in-sample), x/y/z: before "
            + " / ".join(_f(v, ".1f") for v in b["slope_ug_per_k"]) + " µg/K ("
            + " / ".join(_f(v, ".2f") for v in b["drift_mg"]) + " mg over range), after "
            + " / ".join(_f(v, ".2f") for v in a["slope_ug_per_k"]) + " µg/K ("
            + " / ".join(_f(v, ".3f") for v in a["drift_mg"]) + " mg)"
        )
    if "coefficients" in r:
        lines += ["", format_coefficients(fit)]
    tilt = format_tilt_table(fit)
    if tilt:
        lines += ["", tilt]
    return "\n".join(lines)


# --- figures ------------------------------------------------------------------
def write_figures(
    fit: ThermalFit, recording: Recording, out_dir: str | os.PathLike
) -> list[Path]:
    """Write the report's PNG figures into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [_norm_error_figure(fit, recording, out / "norm_error.png")]
    temps = np.array([st.temperature_c for st in fit.model.steps])
    if fit.model.temperature_dependent and temps.size and np.all(np.isfinite(temps)):
        paths.append(_parameters_figure(fit, out / "parameters_vs_temperature.png"))
    else:  # one dot on a "temperature (none)" axis says nothing: say so instead
        note = ("no parameters-vs-temperature figure: the recording has no temperature "
                "(the model is temperature-independent)")
        fit.notes.append(note)
        fit.report.setdefault("notes", []).append(note)
    if fit.model.temperature_dependent and len(fit.steps) >= 2:
        paths.append(_drift_figure(fit, recording, out / "drift.png"))
    return paths


def _norm_error_figure(fit: ThermalFit, rec: Recording, path: Path) -> Path:
    used = np.flatnonzero(fit.row_step >= 0)
    raw = rec.raw_g[used]
    cal = fit.model.compensate(raw, fit.row_temperature_c[used], extrapolate=True)
    g = fit.model.g_local
    before_mg = (np.linalg.norm(raw, axis=1) - g) * 1e3
    after_ug = (np.linalg.norm(cal, axis=1) - g) * 1e6
    steps = fit.row_step[used]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    cmap = step_colormap()
    temps = np.array([st.temperature_c for st in fit.steps])
    finite = np.isfinite(temps)
    tlo, thi = (temps[finite].min(), temps[finite].max()) if finite.any() else (0.0, 1.0)
    for st in fit.steps:
        m = steps == st.step
        frac = 0.5 if not math.isfinite(st.temperature_c) or thi == tlo else \
            (st.temperature_c - tlo) / (thi - tlo)
        label = f"{_f(st.temperature_c, '.0f')} °C" if math.isfinite(st.temperature_c) else None
        ax1.plot(np.flatnonzero(m), before_mg[m], ".", color=cmap(frac), label=label)
        ax2.plot(np.flatnonzero(m), after_ug[m], ".", color=cmap(frac))
    ax1.set_ylabel("raw |g| − g (mg)")
    ax1.set_title(f"|g| error per reading, before and after the thermal model "
                  f"({fit.model.mode} mode, {fit.model.method})")
    ax2.set_ylabel("compensated |g| − g (µg)")
    ax2.set_xlabel("reading index (steps in time order)")
    rms_b = np.sqrt(np.mean(before_mg**2))
    rms_a = np.sqrt(np.mean(after_ug**2))
    ax1.text(0.01, 0.95, f"RMSE {rms_b:.2f} mg", transform=ax1.transAxes, va="top")
    ax2.text(0.01, 0.95, f"RMSE {rms_a:.1f} µg", transform=ax2.transAxes, va="top")
    for a in (ax1, ax2):
        a.grid(alpha=0.3)
    if any(np.isfinite(temps)):
        ax1.legend(fontsize=7, ncol=6, loc="lower right")
    return _save(fig, path)


def step_colormap() -> matplotlib.colors.Colormap:
    """Cold-to-hot colours that all stay visible on white.

    Why not ``coolwarm``: its middle (the 0–10 °C steps of a −40…60 °C
    campaign) is nearly white. ``plasma`` cut at 0.8 runs dark blue (cold) →
    magenta → orange (hot) and never reaches its pale yellow end.
    """
    base = plt.get_cmap("plasma")
    return matplotlib.colors.ListedColormap(base(np.linspace(0.0, 0.8, 256)), "soakcal_steps")


def _parameters_figure(fit: ThermalFit, path: Path) -> Path:
    m = fit.model
    temps = np.array([st.temperature_c for st in m.steps])
    P = np.array([st.params for st in m.steps])
    SE = np.array([st.stderr for st in m.steps])
    fig, axes = plt.subplots(4, 3, figsize=(12, 11), sharex=True)
    has_t = m.temperature_dependent and np.all(np.isfinite(temps))
    grid = np.linspace(*m.valid_c, 200) if has_t and m.valid_c else None
    for k, (name, unit) in enumerate(zip(sfem.PARAM_NAMES, sfem.PARAM_UNITS, strict=True)):
        ax = axes[k // 3][k % 3]
        factor, shown, offset = _DISPLAY[unit]
        label = f"{name} − 1 ({shown})" if offset else f"{name} ({shown})"
        ax.set_ylabel(label)
        if not m.identifiable[k]:
            ax.text(0.5, 0.5, "not identifiable\n(norm mode: |g| cannot see a rotation)",
                    ha="center", va="center", transform=ax.transAxes, fontsize=8)
            continue
        x = temps if has_t else np.zeros(len(temps))
        ax.errorbar(x, (P[:, k] - offset) * factor, yerr=np.nan_to_num(SE[:, k]) * factor,
                    fmt="o", ms=3, capsize=2, label="per-step LM fit ±1σ")
        if grid is not None:
            curve = m.params_vector_at(grid, extrapolate=True)[:, k]
            ax.plot(grid, (curve - offset) * factor, "-", lw=1.2,
                    label=f"degree-{m.degree} polynomial ({m.method})")
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel(f"temperature ({m.temperature_source}, °C)")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"SFEM parameters vs temperature (Eq. 1, Eq. 8), {m.mode} mode")
    # fixed margins: tight_layout on 12 panels costs seconds and changes nothing here
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.06, top=0.95, wspace=0.35, hspace=0.15)
    return _save(fig, path, tight=False)


def _drift_figure(fit: ThermalFit, rec: Recording, path: Path) -> Path:
    """Per-axis change with temperature at fixed orientation, step means (Fig. 11 style)."""
    used = np.flatnonzero(fit.row_step >= 0)
    raw = rec.raw_g[used]
    T = fit.row_temperature_c[used]
    cal = fit.model.compensate(raw, T, extrapolate=True)
    groups = rec.positions()[used]
    steps = fit.row_step[used]

    def centred(v: np.ndarray) -> np.ndarray:
        return metrics.minus_group_means(groups, v)  # one pass, not a mask per position

    before, after = centred(raw), centred(cal)
    st_ids = [st.step for st in fit.steps]
    st_T = np.array([st.temperature_c for st in fit.steps])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    drift = fit.report.get("drift") or {}
    for a, data, scale, unit, key in ((ax1, before, 1e3, "mg", "before"),
                                      (ax2, after, 1e6, "µg", "after")):
        slopes = drift.get(key, {}).get("slope_ug_per_k", [math.nan] * 3)
        for j, axis in enumerate("xyz"):
            means = np.array([data[steps == s, j].mean() for s in st_ids]) * scale
            a.plot(st_T, means, "o-", ms=3, label=f"{axis}: {_f(slopes[j], '.2f')} µg/K")
        a.set_xlabel(f"temperature ({fit.model.temperature_source}, °C)")
        a.set_ylabel(f"output change at fixed orientation ({unit})")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    ax1.set_title("raw (uncompensated)")
    ax2.set_title("compensated (thermal model)")
    fig.suptitle("Thermal drift per axis, mean over positions of each step")
    return _save(fig, path)


def plot_rmse_vs_positions(
    out_path: str | os.PathLike,
    nops: Sequence[int] = schedules.TABLE4_NOP,
    *,
    truth: sfem.SfemParams | None = None,
    noise_g: float = 25e-6 * math.sqrt(31.25) / math.sqrt(200),
    mode: str = "reference",
    seed: int = 0,
    n_heldout: int = 1296,
    repeats: int = 5,
) -> tuple[Path, list[dict[str, float]]]:
    """The seed's Fig. 8 on simulated data: RMSE after calibration vs number of positions.

    For each n in ``nops``: readings at ``schedules.sphere(n)`` from a sensor
    with ``truth`` errors (default: an ADXL355-like set) plus white noise of
    ``noise_g`` per averaged reading (default 25 µg/√Hz, ODR 62.5 Hz, 200
    samples); fit (LM, Eq. 7); report Eq. 9 on the fitted readings and on
    ``n_heldout`` fresh readings (sphere(1296), the seed's §4.2 reference set),
    RMS-averaged over ``repeats`` noise realisations.
    """
    rng = np.random.default_rng(seed)
    p = truth or _example_truth()
    ref_h = schedules.sphere(n_heldout)
    rows = []
    clean_h = p.invert(ref_h)
    for n in nops:
        ref = schedules.sphere(n)
        fit_ms, held_ms, before_ms = [], [], []
        for _ in range(repeats):
            raw = p.invert(ref) + rng.normal(0, noise_g, ref.shape)
            try:
                fr = fit_reference(raw, ref) if mode == "reference" else fit_norm(raw)
            except ValueError:
                break
            raw_h = clean_h + rng.normal(0, noise_g, ref_h.shape)
            fit_ms.append(fr.rmse_norm_ug**2)
            held_ms.append(rmse_norm_ug(fr.params.apply(raw_h)) ** 2)
            before_ms.append(rmse_norm_ug(raw_h) ** 2)
        if not fit_ms:
            continue
        rows.append({
            "positions": n,
            "rmse_fit_ug": float(np.sqrt(np.mean(fit_ms))),
            "rmse_heldout_ug": float(np.sqrt(np.mean(held_ms))),
            "rmse_before_ug": float(np.sqrt(np.mean(before_ms))),
        })
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ns = [r["positions"] for r in rows]
    ax.semilogx(ns, [r["rmse_fit_ug"] for r in rows], "o-", label="fitted positions")
    ax.semilogx(ns, [r["rmse_heldout_ug"] for r in rows], "s-",
                label=f"{n_heldout} held-out positions")
    ax.axhline(noise_g * 1e6, color="grey", ls=":", label="noise of one reading")
    ax.set_xlabel("number of calibration positions (sphere(n))")
    ax.set_ylabel("RMSE of |g| after calibration, Eq. 9 (µg)")
    ax.set_title(f"RMSE vs number of positions ({mode} mode), cf. seed Fig. 8")
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    return _save(fig, Path(out_path)), rows


def _example_truth() -> sfem.SfemParams:
    p = sfem.identity_vector()
    p[sfem.BIAS] = [12e-3, -8e-3, 20e-3]
    p[sfem.SCALE] += [0.008, -0.006, 0.011]
    p[sfem.ALPHA] = [3e-3, -4e-3, 2e-3]
    p[sfem.MISALIGN] = [4e-3, -2e-3, 5e-3]
    return sfem.SfemParams.from_vector(p)


def _save(fig: plt.Figure, path: Path, tight: bool = True) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
