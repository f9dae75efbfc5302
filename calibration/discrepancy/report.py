"""Readable text report and figures of a :class:`~calibration.discrepancy.Diagnosis`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from calibration.discrepancy.diagnose import null_method


def text_report(diag: Any) -> str:
    lines = [f"Mismatch diagnosis of {diag.recording} ({diag.mode} mode)",
             f"  base model sfem-cubic: residual RMS {diag.rmse_ug:.1f} µg, "
             f"noise {diag.noise_ug:.1f} µg ({diag.noise_source})",
             f"  null: {null_method()}, {diag.n_null} replicates, "
             f"family-wise α = {diag.alpha}",
             f"  held out: {diag.heldout_scheme}"]
    if getattr(diag, "cannot_judge", ""):
        return "\n".join(lines[:1] + [f"  Cannot judge: {diag.cannot_judge}."])
    excess = excess_line(getattr(diag, "unexplained", None) or {})
    if not diag.findings:
        # "Consistent with noise" only where the residuals are: a χ² well above the recorded
        # noise that no test could place is said, not called noise.
        lines.append("  No mismatch: the residuals are consistent with noise." if not excess
                     else "  No effect found at the family-wise level, but the residuals are "
                     "not at the recorded noise:")
    for k, f in enumerate(diag.findings, 1):
        w = f.where
        lines += [
            f"{k}. {f.effect} ({', '.join(f.axes)}), p = {f.p_value:.2g}",
            f"   {f.explanation}",
            f"   where: steps {w.get('steps')}, positions {w.get('positions')}, "
            f"t = {w['time_s'][0]:.0f}–{w['time_s'][1]:.0f} s",
        ]
        # Nothing modelled (unexplained, one plateau's structure): no before/after.
        if f.effect != "unexplained" and np.isfinite(f.heldout_rmse_before_ug):
            lines.append(f"   RMS {f.rmse_before_ug:.1f} → {f.rmse_after_ug:.1f} µg; held out "
                         f"{f.heldout_rmse_before_ug:.1f} → {f.heldout_rmse_after_ug:.1f} µg")
        alike: dict[str, list[str]] = {}  # alternatives the protocol cannot rule out, by why
        for c in f.confusers:
            if c.get("p_before") is None:
                alike.setdefault(c["how_told_apart"], []).append(c["effect"])
                continue
            after = c.get("p_after")
            lines.append(f"   told apart from {c['effect']} (p {c['p_before']:.2g}"
                         + (f" → {after:.2g} after this term" if after is not None else "")
                         + f"): {c['how_told_apart']}")
        for why, effs in alike.items():
            lines.append(f"   not told apart from {', '.join(effs)}: {why}")
    if excess and not any(f.where.get("spread") for f in diag.findings):
        lines.append(excess)  # (the excess's own finding says it already)
    lines += protocol_lines(getattr(diag, "protocol", None) or {})
    if diag.not_identifiable:
        lines.append("Not identifiable in this recording:")
        for n in diag.not_identifiable:
            lines.append(f"  - {n['effect']}: {n['why']}. Experiment: {n['experiment']}.")
    for note in diag.notes:
        lines.append(f"Note: {note}")
    return "\n".join(lines)


def excess_line(unexplained: dict[str, Any]) -> str:
    """What the χ² excess test says, when it is significant (docs/diagnosis.md §7).

    The test does not enter the verdict (its null, sd/√n, is often optimistic on real
    averages), but a residual several times the recorded noise that no finding explains is
    what a reader must not take for a fit at the noise: the report says how far above it
    the final residual is and that no test placed it.
    """
    c = unexplained.get("chi_square") or {}
    if not c.get("significant"):
        return ""
    where = ("the scan found no step or position block that stands out"
             if unexplained.get("blocks") else
             "the recording has no repeated step or position for the scan to place it")
    return (f"  Left unexplained: the final residual is {c['rms_over_noise']:.2f} × the "
            f"recorded noise (χ²/dof {c['chi2_per_dof']:.2f} on {c['dof']} dof, "
            f"p = {c['p_value']:.2g}); {where}. Either the recorded noise understates the "
            "scatter (correlated samples, vibration, placement repeatability) or structure "
            "the catalogue does not name is spread over the recording: repeat positions "
            "or plateaus to locate it.")


def protocol_lines(pr: dict[str, Any]) -> list[str]:
    """The short "what this protocol separates" section (docs/diagnosis.md §11)."""
    if not pr:
        return []
    temp = ("no temperature recorded" if pr["temperature"] == "none" else
            f"{pr['temperature']} over {pr['n_plateaus']} plateau(s) ({pr['temperature_source']})")
    sessions = ("no session column" if pr["sessions"] is None
                else f"{pr['sessions']} session(s) recorded")
    lines = ["Protocol: " + "; ".join([
        temp, f"position order {pr['position_order']} (from {pr['order_from']})",
        ("references and the table's poses" if pr.get("table_poses") else "references")
        if pr["references"] else "no references (norm mode)", sessions,
        "oblique positions" if pr["oblique_positions"] else "axis-aligned positions only"])]
    if pr["separable"]:
        lines.append(f"  separates: {', '.join(pr['separable'])}")
    for c in pr["not_separable"]:
        tail = " (a finding naming one is reported as not identifiable)" \
            if c["finding_withheld"] else ""
        versus = c.get("versus") or []
        # Two sides (time terms versus orientation terms): each is confused with the other
        # side only, so the line says which from which, not one group of all of them.
        group = (" / ".join(e for e in c["effects"] if e not in versus) + " from "
                 + " / ".join(versus)) if versus else " / ".join(c["effects"])
        outside = c.get("outside_catalogue") or []
        if outside:
            group += " from " + " / ".join(outside)
        how = f"; to separate them: {c['experiment']}" if c.get("experiment") else ""
        lines.append(f"  cannot separate {group}: {c['why']}{tail}{how}")
    return lines


def write_diagnosis_figures(diag: Any, out_dir: str | Path) -> list[Path]:
    """Residuals by step, by position and over time, before and after; found regions shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    before, after = diag.residuals_before_ug, diag.residuals_after_ug
    labels = ["x", "y", "z"] if before.shape[1] == 3 else ["|g|"]
    paths = []
    fig, axs = plt.subplots(len(labels), 1, figsize=(10, 2.4 * len(labels)), sharex=True,
                            squeeze=False)
    for a, lab in enumerate(labels):
        ax = axs[a, 0]
        ax.plot(diag.t_s / 3600, before[:, a], ".", ms=3, label="base model")
        ax.plot(diag.t_s / 3600, after[:, a], ".", ms=3, label="with findings")
        for f in diag.findings:
            if not f.where.get("time_s"):
                continue
            lo, hi = f.where["time_s"]
            ax.axvspan(lo / 3600, hi / 3600, alpha=0.08, color="C3")
        ax.set_ylabel(f"{lab} residual, µg")
    axs[0, 0].legend(loc="upper right", fontsize=8)
    axs[-1, 0].set_xlabel("elapsed time, h")
    # Say "shaded" only when something is: a recording with no finding has no region.
    shaded = any(f.where.get("time_s") for f in diag.findings)
    fig.suptitle("Residuals over time" + (" (shaded: where findings act)" if shaded
                                          else " (no finding: nothing shaded)"))
    fig.tight_layout()
    p = out / "residuals_time.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    for key, name in ((diag.steps, "step"), (diag.positions, "position")):
        fig, ax = plt.subplots(figsize=(10, 3))
        ids = np.unique(key)
        rb = [np.sqrt(np.mean(before[key == k] ** 2)) for k in ids]
        ra = [np.sqrt(np.mean(after[key == k] ** 2)) for k in ids]
        ax.bar(ids - 0.2, rb, 0.4, label="base model")
        ax.bar(ids + 0.2, ra, 0.4, label="with findings")
        ax.axhline(diag.noise_ug, color="k", lw=0.8, ls="--", label="noise")
        hot = {k for f in diag.findings for k in f.where.get(name + "s", [])}
        for k in hot:
            ax.axvspan(k - 0.5, k + 0.5, alpha=0.08, color="C3")
        ax.set_xlabel(name)
        ax.set_ylabel("RMS residual, µg")
        ax.legend(fontsize=8)
        fig.tight_layout()
        p = out / f"residuals_by_{name}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
    return paths
