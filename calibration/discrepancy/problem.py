"""The base model, linearised over the whole recording (docs/diagnosis.md §1).

Reference mode: the SFEM (seed Eq. 1) solved for the raw output is
``raw = A(T)⁻¹ ref + b(T)``; with each SFEM parameter a cubic in T (seed Eq. 8)
the entries of ``G = A⁻¹`` are cubics up to higher powers of T (products of
tempcos), so per axis::

    raw_a = Σ_j Σ_p β[a,j,p] · u_j · t^p,   u = (1, ref_x, ref_y, ref_z), p = 0..3

48 coefficients (12 parameters × 4 powers), a block-diagonal design with the
SFEM-cubic's tangent space. What the SFEM-cubic predicts beyond that span (the
higher powers: up to a few µg at the ends of −40…60 °C) is taken from a joint
fit of the SFEM-cubic itself and removed from the data (:func:`_sfem_remainder`),
so the linear problem has the SFEM-cubic's residuals, not its surrogate's.
Norm mode linearises ``|A(T)(raw − b(T))| − 1`` around a Gauss–Newton fit of
the 9 identifiable parameters (M is invisible to |g|) × powers of T.

Everything is whitened by σ = sd/√n (or a residual estimate when sd is
absent), plus the recorded temperature's own noise through ∂raw/∂T, so that
statistics are in units of the noise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibration import fit as sfem_fit
from calibration import sfem
from calibration.discrepancy.context import DesignContext, base_context
from calibration.recording import Recording

Lift = Callable[[np.ndarray], np.ndarray]
# (rows (r,), raw-space values on those rows (r,3,k)) → (residual entries, (entries, k) values)
LiftRows = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass
class LinearProblem:
    """``y = X0·β + (effect columns)·θ + noise`` in residual space (m entries)."""

    mode: str
    y: np.ndarray  # (m,) data vector (raw output, or norm residual of the base fit), g
    X0: np.ndarray | AxisBlockDesign  # (m, p0) base design, unweighted
    w: np.ndarray  # (m,) whitening weights 1/σ
    row: np.ndarray  # (m,) reading index of each entry
    axis: np.ndarray  # (m,) axis of each entry (−1 in norm mode)
    lift: Lift  # raw-space (N,3,k) → residual space (m,k)
    ctx: DesignContext
    noise_from_sd: bool
    degree: int
    t_mid_c: float
    t_half_c: float
    # The lift of columns that live on a few readings only (the scan's local blocks): the
    # same values as ``lift`` on those readings' entries, without an (m × k) dense copy
    # that is zero almost everywhere (issue 10: O(rows) per block made the scan O(rows²)).
    lift_rows: LiftRows | None = None
    # (m,) whitened loading of each entry on its reading's one temperature error, 0 when
    # none: the recorded T's noise moves the three axes of a reading together (ε_a =
    # ∂raw_a/∂T · δT), so whitened entries of one reading are correlated. The parametric
    # bootstrap draws that shared term (stats.null_replicates); without it the null of any
    # statistic that sums a reading's axes (outliers, cross-axis terms) was too light.
    shared_t_loading: np.ndarray | None = None
    # Only when the readings are capture means of raw samples (samples.py): σ² = κ·sd²/n
    # + τ², κ the samples' averaging shortfall and τ (g) the error a capture shares, both
    # fitted to the residual (capture_noise).
    between_sd_g: float | None = None
    scatter_factor: float | None = None
    # σ fitted to each plateau's own affine residual (within_step_residual), not to the
    # base residual: the χ² of the final residual against it still tests between-plateau
    # structure (diagnose._excess_test).
    noise_within_plateaus: bool = False

    @property
    def m(self) -> int:
        return self.y.size

    def whiten(self, a: np.ndarray) -> np.ndarray:
        return a * (self.w if a.ndim == 1 else self.w[:, None])


# Noise of every recording with sd_* columns: κ·sd²/n + τ² fitted to its base residual
# (capture_noise), not sd/√n alone (issue 22: placement and slow vibration flagged nulls).
SCATTER_FROM_RESIDUAL = True


def pooled_sigma_g(rec: Recording, steps: np.ndarray) -> np.ndarray | None:
    """σ of each reading: the per-(step, axis) median of ``sd_*`` over √n.

    Why: each row's own sd is itself a noisy estimate (χ with n−1 dof); whitening
    by it gives heavier-than-Gaussian tails and false outliers. Pooling per step
    keeps real changes of the noise (vibration, temperature) and drops the χ noise.
    """
    if rec.sigma_g is None:
        return None
    sd = np.column_stack([rec.columns[c] for c in ("sd_x", "sd_y", "sd_z")])
    n = rec.columns.get("n")
    n = np.ones(len(rec)) if n is None else np.where(np.isfinite(n) & (n > 0), n, 1.0)
    pooled = np.empty_like(sd)
    for s_ in np.unique(steps):
        m = steps == s_
        pooled[m] = np.nanmedian(sd[m], axis=0)
    return pooled / np.sqrt(n)[:, None]


def temperature_noise_c(ctx: DesignContext) -> np.ndarray:
    """Per-reading noise of the recorded temperature (°C), 0 without temperature.

    Robust sd of first differences within each plateau / √2 (insensitive to slow
    settling), pooled by the median over plateaus (one plateau's 20-odd differences
    give a noisy estimate; the chamber PV noise does not change from step to step).
    """
    if ctx.temperature_source == "none":
        return np.zeros(ctx.n)
    per_step = []
    for s_ in ctx.step_ids:
        m = np.flatnonzero(ctx.steps == s_)
        if m.size < 3:
            continue
        d = np.diff(ctx.temp_c[m[np.argsort(ctx.t_s[m], kind="stable")]])
        per_step.append(1.4826 * float(np.median(np.abs(d - np.median(d)))) / np.sqrt(2.0))
    return np.full(ctx.n, float(np.median(per_step)) if per_step else 0.0)


# The least κ₀ (the factor on the sensor's own sd²/n): a capture mean of a sensor's noise
# averages at most this much faster than white. Why (issue 22): κ₀ is fitted to the
# within-plateau residuals, and where the quietest plateau has too few readings for a
# residual of its own (10 on a 12-position schedule) none of them sits at the floor: κ₀
# went to the old bound 10⁻³ while κ took the other plateaus' noise, and that plateau's σ
# came out 0.4 µg against 9 µg of sd/√n (the second generator's null 0224, unseen protocols:
# a χ² excess of 9 on 207 dof). Measured on the shared real recordings the ADXL355's own
# noise averages at 0.4–0.5 × white; 0.1 leaves that margin and bounds what an
# unconstrained κ₀ can claim.
KAPPA0_MIN = 0.1
FAR_ALPHA = 0.01  # entries beyond this family-wise χ²₁ tail do not set the noise (capture_noise)


def capture_noise(e: np.ndarray, sig: np.ndarray, dof_corr: float,
                  known_var: np.ndarray | None = None, floor: np.ndarray | None = None,
                  across: np.ndarray | None = None) -> tuple[np.ndarray, float, float]:
    """σ of capture means from their base residual: ``(σ, κ, τ)``, σ² = κ·sd²/n + τ².

    ``e`` (N, a) is the base residual of the capture means, ``sig`` (N, a) their sd/√n
    (pooled per step and axis). A mean's error is not its samples' scatter over √n
    alone: samples correlated in time (slow vibration, 1/f noise) average down more
    slowly (κ ≥ 1, in proportion to the scatter, so it grows on vibrating steps), and
    what a capture shares whatever its scatter — its placement on the table, the
    temperature state — adds τ², the same at every step and axis. Neither shows in the
    scatter. Both are fitted by Gaussian maximum likelihood to all residuals at once
    (dof-corrected for the base's p columns): per-step moment estimates from ~24
    residuals each were noisy enough to misweight steps and axes and raised the false
    alarms (docs/benchmarks.md, *Raw-sample recordings*). When the steps' sd²/n are
    nearly equal, κ and τ trade off along a ridge of the likelihood on which σ, all
    the whitening needs, hardly changes.

    ``known_var`` (N, a): variance already known per entry (the temperature channel's
    noise through ∂raw/∂T), added to the model, not fitted: fitted before it, τ took the
    temperature noise in and the term was then added a second time.

    ``floor`` (N, a): the sensor's own sd²/n (the quietest plateau's scatter). With it the
    scatter above the floor — a bench's vibration — gets a factor of its own:
    σ² = κ₀·floor + κ·(sd²/n − floor) + τ². Why (issue 22): a sensor's noise and a slow
    vibration average down differently within a capture (measured on the shared real
    recordings: 0.4–0.5 × white for the ADXL355's own noise, up to 20× for slow bench
    motion); one κ for both over-stated the quiet plateaus' noise threefold, the outlier
    test's global scale sat at their level and vibrating plateaus' readings were outliers.

    ``across`` (N, a): ``1 − û_a²`` of each entry (û the unit reference). Re-seating the
    sensor at each visit turns it by a small random angle δθ (per-axis rms ρ, isotropic):
    the output error δθ × f has variance ρ²·(1 − f_a²) on axis a — none on the axis along
    gravity, most on the axes across it, the same at every visit of a position. Fitted as
    ρ² with κ and τ. Why (issue 22): one τ² for all entries under-stated the axes across
    gravity and over-stated the one along it, so a position×axis block of the localised
    scan stood out on null recordings with placement error.

    Entries far beyond the fitted σ (χ²₁ tail below :data:`FAR_ALPHA` over all entries)
    are left out and the fit repeated once: the noise an outlier is judged against must
    not be raised by the outlier (issue 22: two readings 8 σ off on one plateau doubled
    κ, and both were then missed).
    """
    from scipy.optimize import minimize
    from scipy.stats import chi2

    sig2 = np.asarray(sig, float) ** 2
    known = np.zeros_like(sig2) if known_var is None else np.asarray(known_var, float)
    fl_all = np.zeros_like(sig2) if floor is None else np.minimum(floor, sig2)
    e2 = (np.asarray(e, float) * dof_corr) ** 2
    ac_all = np.zeros_like(sig2) if across is None else np.asarray(across, float)
    ok = np.isfinite(e2) & np.isfinite(sig2) & (sig2 > 0)
    # Every entry usable (the rule): the arrays themselves, not copies (issue 22, memory:
    # each is 24 MB at 1 M readings, and the likelihood below took more copies per call).
    w, e2, kv, fl, ac = ((a.ravel() for a in (sig2, e2, known, fl_all, ac_all)) if ok.all()
                         else (a[ok] for a in (sig2, e2, known, fl_all, ac_all)))
    w0 = float(np.median(w))

    def var(q: np.ndarray, w_: np.ndarray, fl_: np.ndarray, kv_: np.ndarray,
            ac_: np.ndarray) -> np.ndarray:
        # κ = 1 + q0 on the scatter above the floor, κ₀ = q2 on the floor, τ² = q1·w0,
        # ρ² = q3·w0 across the reference; in place, in the order of
        # (1 + q0)·(w − fl) + q2·fl + q1·w0 + (q3·w0)·ac + kv
        v = w_ - fl_
        v *= 1.0 + q[0]
        v += q[2] * fl_
        v += q[1] * w0
        v += q[3] * w0 * ac_
        v += kv_
        return v

    keep = np.ones(w.size, bool)
    kept = (w, e2, kv, fl, ac)  # the entries the likelihood reads: all, until some are far

    def nll(q: np.ndarray) -> float:
        w_, e2_, kv_, fl_, ac_ = kept
        v = var(q, w_, fl_, kv_, ac_)
        lv = np.log(v)
        lv += np.divide(e2_, v, out=v)  # log v + e²/v
        return float(np.sum(lv)) / int(keep.sum())

    start = np.array([0.0, max(0.0, float(np.mean(e2 - w - kv)) / w0), 1.0, 0.0])
    q0_bounds = (0.0, 1e6) if floor is None else (KAPPA0_MIN, 1e4)
    bounds = [(0.0, 1e4), (0.0, 1e6), (1.0, 1.0) if floor is None else q0_bounds,
              (0.0, 0.0) if across is None else (0.0, 1e6)]
    # Why the tight tolerances: with four parameters the default stop left σ at ~1e-6
    # relative, enough to differ between the dense and the row-block design (issue 10).
    opts = {"ftol": 1e-14, "gtol": 1e-12, "maxiter": 2000}
    q = minimize(nll, start, method="L-BFGS-B", bounds=bounds, options=opts).x
    far = e2 / var(q, w, fl, kv, ac) > chi2.isf(FAR_ALPHA / max(w.size, 1), 1)
    if far.any() and int((~far).sum()) >= w.size // 2:
        keep = ~far
        kept = tuple(a[keep] for a in (w, e2, kv, fl, ac))
        q = minimize(nll, q, method="L-BFGS-B", bounds=bounds, options=opts).x
    kappa, tau2 = 1.0 + float(q[0]), float(q[1]) * w0
    return np.sqrt(var(q, sig2, fl_all, known, ac_all)), kappa, float(np.sqrt(tau2))


def _n_of(rec: Recording) -> np.ndarray:
    n = rec.columns.get("n")
    return np.ones(len(rec)) if n is None else np.where(np.isfinite(n) & (n > 0), n, 1.0)


def within_step_residual(raw: np.ndarray, ref: np.ndarray, ctx: DesignContext) -> np.ndarray:
    """Residual (N,3) of each plateau's own affine fit, scaled to unit dof (NaN where too few).

    Columns per step and axis: (1, ref_x, ref_y, ref_z) × (1, t − t̄, (t − t̄)²) and T − T̄
    (fewer powers of t on a plateau with few readings). Why (issue 22):
    the noise the recording itself shows must not include the effects under test; the base
    residual does (a strong lag raised σ 30-fold), but every catalogue effect that is a bias
    or scale change of a plateau, or a slow trend of them within it, is absorbed here. What stays
    is placement, vibration and the temperature channel's reading-to-reading noise.
    """
    from scipy.stats import chi2

    e = np.full(raw.shape, np.nan)
    for k in np.unique(ctx.steps):
        m = np.flatnonzero(ctx.steps == k)
        dt_h = (ctx.t_s[m] - ctx.t_s[m].mean()) / 3600.0
        u = np.column_stack([np.ones(m.size), ref[m]])
        dT = (ctx.temp_c[m] - ctx.temp_c[m].mean())[:, None]
        far_q = float(chi2.isf(FAR_ALPHA / m.size, 3))
        first = None
        for powers in (3, 2, 1):  # the richest trend the plateau's readings can carry
            X = np.hstack([u * (dt_h**p)[:, None] for p in range(powers)] + [dT])
            if m.size - np.linalg.matrix_rank(X) < MIN_STEP_DOF:
                continue
            r, settled = _plateau_residual(X, raw[m], far_q)
            first = r if first is None else first
            if settled:  # else a reading far off needs a plateau fit with fewer columns
                e[m] = r
                break
        else:
            if first is not None:
                e[m] = first
    return e


def _plateau_residual(X: np.ndarray, y: np.ndarray, far_q: float
                      ) -> tuple[np.ndarray, bool]:
    """One plateau's residual (n, 3) of its own fit, scaled to unit dof; NaN for a reading
    far off: its studentized residual (χ²₃ against the plateau's robust scale) beyond
    ``far_q``, refitted out (twice at most, so a second reading is not masked by a first).
    The flag is False where a reading is far off but the plateau has too few readings to
    refit it out with these columns (the caller tries fewer).

    Why (issue 22): the plateau's fit has 9–13 columns on 18–24 readings (leverage about
    0.5), so one reading far off is spread into every other reading's residual: on the
    second generator an outlier at twice its detectable size raised its plateau's σ by up
    to a quarter (:func:`step_inflation`), its neighbours' statistics fell, and the outlier
    test's tail estimate (then stats.reading_tail_dof) read that as a heavier tail than the
    noise has (ν 8–22 where the same protocol's nulls gave a median ν > 50). A reading far
    off is the outlier test's question, not the plateau's noise.
    """
    keep = np.ones(y.shape[0], bool)
    settled = True
    for npass in range(FAR_PASSES + 1):
        Xk = X[keep]
        rank = int(np.linalg.matrix_rank(Xk))
        r = y - X @ np.linalg.lstsq(Xk, y[keep], rcond=None)[0]
        k = int(keep.sum())
        if not ROBUST_PLATEAU_FIT or npass == FAR_PASSES:
            break
        h = np.clip(np.einsum("ij,ji->i", Xk, np.linalg.pinv(Xk)), 0.0, 1.0 - 1e-9)
        d = r[keep] / np.sqrt(1.0 - h)[:, None]  # each entry at the noise's scale
        sd = 1.4826 * np.median(np.abs(d), axis=0)
        far = np.sum((d / np.maximum(sd, 1e-300)) ** 2, axis=1) > far_q
        if not far.any():
            break
        trial = keep.copy()
        trial[np.flatnonzero(keep)[far]] = False
        if int(trial.sum()) - int(np.linalg.matrix_rank(X[trial])) < MIN_STEP_DOF:
            settled = False
            break
        keep = trial
    out = r * np.sqrt(k / (k - rank))
    out[~keep] = np.nan
    return out, settled


MIN_STEP_DOF = 6
# A reading far off does not set its plateau's noise (_plateau_residual): beyond χ²₃'s
# FAR_ALPHA / (the plateau's readings) point, refitted out at most FAR_PASSES times.
ROBUST_PLATEAU_FIT = True
FAR_PASSES = 2
STEP_PRIOR_ENTRIES = 6.0  # shrinkage of a step's scatter ratio towards 1 (entries' worth)


def step_inflation(e: np.ndarray, sig: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Per-reading factor ≥ 1 on σ where a plateau scatters more than the noise model says.

    Why (issue 22): sources average down differently — a bench's slow vibration barely
    averages within a short capture, a sensor's own noise may average faster than white —
    so one κ for all plateaus over-states the quiet ones' noise and under-states the
    vibrating ones'. The global robust scale of the outlier test then sits at the quiet
    level and the vibrating plateaus' largest readings were called outliers on null
    recordings. The ratio is robust (median of (e/σ)², χ²₁'s median 0.455), so an outlier
    does not raise its own plateau's noise (the mean did: 2 of 18 outliers at twice their
    detectable size were missed on the project's blind benchmark), shrunk towards 1 by
    ``STEP_PRIOR_ENTRIES`` entries, and it only inflates: a quiet plateau keeps its σ
    (deflating it moved the held-out comparison of accepted terms on ordinary recordings).
    """
    z2 = (np.asarray(e, float) / np.asarray(sig, float)) ** 2
    out = np.ones(len(steps))
    for k in np.unique(steps):
        m = steps == k
        vals = z2[m].ravel()
        vals = vals[np.isfinite(vals)]
        if vals.size == 0:
            continue
        ratio = float(np.median(vals)) / CHI2_1_MEDIAN
        shrunk = (vals.size * ratio + STEP_PRIOR_ENTRIES) / (vals.size + STEP_PRIOR_ENTRIES)
        out[m] = np.sqrt(max(1.0, shrunk))
    return out


CHI2_1_MEDIAN = 0.4549364231195724


def build_problem(rec: Recording, *, capture_means: bool = False) -> LinearProblem:
    """The linearised base model of ``rec`` (docs/diagnosis.md §1).

    ``capture_means``: the readings are means of raw-sample captures
    (:mod:`calibration.discrepancy.samples`): σ gains the between-capture sd τ.
    """
    if rec.has_reference:
        return _reference_problem(rec, capture_means)
    return _norm_problem(rec, capture_means)


def _powers(temp: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, int, float, float]:
    n_temps = len({round(float(np.median(temp[steps == s])), 1) for s in np.unique(steps)})
    degree = int(max(0, min(3, n_temps - 1)))
    lo, hi = float(np.min(temp)), float(np.max(temp))
    mid, half = (lo + hi) / 2.0, max((hi - lo) / 2.0, 1e-6)
    t = (temp - mid) / half
    return np.column_stack([t**p for p in range(degree + 1)]), degree, mid, half


def _reference_problem(rec: Recording, capture_means: bool = False) -> LinearProblem:
    raw, ref = rec.raw_g, rec.ref_g
    assert ref is not None
    n = raw.shape[0]
    ctx = base_context(rec, "reference", ref)
    P, degree, mid, half = _powers(ctx.temp_c, ctx.steps)
    u = np.column_stack([np.ones(n), ref])  # (N,4)
    block = (u[:, :, None] * P[:, None, :]).reshape(n, -1)  # (N, 4·(d+1))
    k = block.shape[1]
    X0 = axis_block_design(block)
    y = raw.ravel()
    sig = pooled_sigma_g(rec, ctx.steps)
    from_sd = sig is not None and bool(np.all(np.isfinite(sig) & (sig > 0)))
    if not from_sd:
        beta = _wls(X0, np.ones(3 * n), y)
        e = (y - X0 @ beta).reshape(n, 3)
        dof_corr = np.sqrt(3 * n / max(3 * n - X0.shape[1], 1))
        s = 1.4826 * np.median(np.abs(e - np.median(e, axis=0)), axis=0) * dof_corr
        sig = np.broadcast_to(np.maximum(s, 1e-9), (n, 3))
    tau = kappa = local = None
    sig_sd = np.asarray(sig, float)
    w = 1.0 / sig_sd.ravel()
    beta = _wls(X0, w, y)
    sig_T = temperature_noise_c(ctx)
    t_part = np.zeros((n, 3))
    if np.any(sig_T > 0) and degree > 0:
        # Errors in the temperature regressor: a reading's T noise moves the model along
        # ∂raw/∂T. Without it, a sensor with a large tempco read on a noisy chamber PV
        # shows "outliers" and lag-like patterns that are only temperature noise.
        dP0 = np.column_stack([np.zeros(n)] + [p_ * P[:, p_ - 1] for p_ in
                                               range(1, degree + 1)]) / half
        db0 = (u[:, :, None] * dP0[:, None, :]).reshape(n, -1)
        d0 = np.column_stack([db0 @ beta[a * k:(a + 1) * k] for a in range(3)])
        t_part = d0 * sig_T[:, None]
        sig = np.sqrt(sig_sd**2 + t_part**2)
        beta = _wls(X0, 1.0 / sig.ravel(), y)
    if from_sd and (capture_means or SCATTER_FROM_RESIDUAL):
        # The recording's own scatter (issue 22): sd/√n misses what a capture shares
        # (placement, slow vibration), unequally from step to step; an outlier or a local
        # block must stand out from that, not from sd/√n. κ, τ are fitted with the
        # temperature term known (capture_noise), so it is not counted twice.
        local = None if capture_means else within_step_residual(raw, ref, ctx)
        if local is None or not np.any(np.isfinite(local)):  # plateaus too small: base's
            e = (y - X0 @ beta).reshape(n, 3)
            dof_corr = float(np.sqrt(3 * n / max(3 * n - X0.shape[1], 1)))
        else:
            e, dof_corr = local, 1.0
        floor = None
        if local is not None:  # the quietest plateau's sd, per axis, at each row's n
            sd_n = sig_sd * np.sqrt(_n_of(rec))[:, None]
            floor = (np.min(sd_n, axis=0)[None, :] / np.sqrt(_n_of(rec))[:, None]) ** 2
        unit = ref / np.linalg.norm(ref, axis=1, keepdims=True)
        sig, kappa, tau = capture_noise(e, sig_sd, dof_corr, t_part**2, floor, 1.0 - unit**2)
        if local is not None:  # the plateau's level scales what is not the T channel's
            f = step_inflation(e, sig, ctx.steps)[:, None]
            sig = np.sqrt(f**2 * np.maximum(sig**2 - t_part**2, 0.0) + t_part**2)
        beta = _wls(X0, 1.0 / sig.ravel(), y)
    w = 1.0 / np.asarray(sig, float).ravel()
    loading = t_part.ravel() * w if np.any(t_part != 0) else None  # |loading| ≤ 1
    t_scaled = P[:, 1] if degree > 0 else np.zeros(n)
    remainder = _sfem_remainder(raw, ref, np.asarray(sig, float).reshape(n, 3), t_scaled,
                                degree, ctx, beta, X0, w)
    if remainder is not None:  # the data minus what the SFEM-cubic has beyond the design

        y = (raw - remainder).ravel()
        beta = _wls(X0, w, y)
    ydata = y.reshape(n, 3)

    def blocks(temp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = (temp - mid) / half
        Pt = np.column_stack([t**p for p in range(degree + 1)])
        dP = np.column_stack([np.zeros(n)] + [p * t ** (p - 1) for p in range(1, degree + 1)])
        return ((u[:, :, None] * Pt[:, None, :]).reshape(n, -1),
                (u[:, :, None] * (dP / half)[:, None, :]).reshape(n, -1))

    # ∂raw/∂T of the fitted base (norm-mode-compatible fallback for temperature effects).
    dblock = blocks(ctx.temp_c)[1]
    ctx.draw_dtemp_g_per_c = np.column_stack([dblock @ beta[a * k:(a + 1) * k] for a in range(3)])
    wn = w.reshape(n, 3)

    def refit_shift(dT_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Base refitted with the die at ``T + dT``: output change from T to T + dT and ∂/∂T there.

        Why: the base fitted on the recorded (air) temperature has absorbed part of a
        lag and is linear only near T; refitting it on the candidate die temperature
        and differencing the cubic is exact for any lag size (docs/diagnosis.md §4).
        """
        b1, d1 = blocks(ctx.temp_c + dT_c)
        b0 = blocks(ctx.temp_c)[0]
        shift = np.empty((n, 3))
        deriv = np.empty((n, 3))
        for a in range(3):
            ba = np.linalg.lstsq(b1 * wn[:, a, None], ydata[:, a] * wn[:, a], rcond=None)[0]
            shift[:, a] = (b1 - b0) @ ba
            deriv[:, a] = d1 @ ba
        return shift, deriv

    ctx.refit_shift = refit_shift

    def lift(x: np.ndarray) -> np.ndarray:
        return x.reshape(3 * n, -1)

    def lift_rows(rows: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (3 * rows[:, None] + np.arange(3)).ravel(), x.reshape(3 * rows.size, -1)

    return LinearProblem(
        "reference", y, X0, w, np.repeat(np.arange(n), 3), np.tile(np.arange(3), n), lift, ctx,
        from_sd, degree, mid, half, lift_rows,
        loading if loading is not None and np.any(loading != 0) else None, tau, kappa,
        noise_within_plateaus=local is not None and np.any(np.isfinite(local)),
    )


def _wls(X: np.ndarray, w: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Weighted least squares ``min ‖w(y − Xβ)‖``: lstsq, or normal equations by row blocks
    for a design above ``stats.TALL_BYTES``.

    Why: lstsq on ``X·w`` holds the weighted copy plus LAPACK's copy and workspace (~4 × the
    design at its peak); on a long recording that, not the data, set diagnose's peak. The
    normal equations on unit-norm columns lose precision only as cond² (the base design's
    condition is modest after scaling); recordings below the size keep lstsq exactly.
    """
    from calibration.discrepancy import stats

    if X.nbytes <= stats.TALL_BYTES or X.shape[0] <= 20 * X.shape[1]:
        return np.linalg.lstsq(X * w[:, None], y * w, rcond=None)[0]
    p = X.shape[1]
    G, h = np.zeros((p, p)), np.zeros(p)
    for sl in stats.row_blocks(X.shape[0], p):
        Xc = X[sl] * w[sl, None]
        G += Xc.T @ Xc
        h += Xc.T @ (y[sl] * w[sl])
    d = np.sqrt(np.diag(G))
    d = np.where(d > 0, d, 1.0)
    beta = np.linalg.lstsq(G / np.outer(d, d), h / d, rcond=1e-12)[0]
    return beta / d


def axis_block_design(block: np.ndarray) -> np.ndarray | AxisBlockDesign:
    """The reference-mode base design: entry (i, a) holds ``block[i]`` in axis a's columns.

    Dense as before up to ``stats.TALL_BYTES``; above, :class:`AxisBlockDesign` keeps the
    (N × k) block only (issue 10: two thirds of the dense (3N × 3k) array are zeros, 1.15 GB
    at 1 M readings, alive for the whole diagnosis).
    """
    from calibration.discrepancy import stats

    n, k = block.shape
    if 8 * 9 * n * k > stats.TALL_BYTES and n > 20 * k:  # the tall paths only
        return AxisBlockDesign(block)
    return _axis_blocks(block)


def _axis_blocks(block: np.ndarray) -> np.ndarray:
    """Dense (3N × 3k) rows of an (N × k) block: reading i, axis a → row 3i + a."""
    n, k = block.shape
    X0 = np.zeros((n, 3, 3 * k))
    for a in range(3):
        X0[:, a, a * k:(a + 1) * k] = block
    return X0.reshape(3 * n, 3 * k)


class AxisBlockDesign:
    """(3N × 3k) block-diagonal-by-axis design stored as its (N × k) block.

    Rows are readings × axes (reading i, axis a at row 3i + a), as the dense form. What the
    tall code paths use: ``shape``, ``nbytes`` (the dense size, so the same paths are
    chosen), contiguous row slices ``[i:j]`` and 1-D row indices (dense rows: the same
    values, zeros included), ``@`` a coefficient vector or matrix, and ``np.asarray``/``*``
    (the dense array, built on demand: only the rarely taken paths need it).
    """

    ndim = 2
    dtype = np.dtype(float)

    def __init__(self, block: np.ndarray) -> None:
        self.block = np.asarray(block, float)
        n, k = self.block.shape
        self.shape = (3 * n, 3 * k)

    @property
    def nbytes(self) -> int:
        return 8 * self.shape[0] * self.shape[1]

    def __getitem__(self, key: object) -> np.ndarray:
        if not isinstance(key, slice):
            idx = np.asarray(key)
            if idx.ndim == 1 and idx.dtype.kind in "iu":  # rows by index: those readings only
                return self._rows_at(idx)
            return np.asarray(self)[key]
        i, j, stride = key.indices(self.shape[0])
        if stride != 1:
            return np.asarray(self)[key]
        if j <= i:
            return np.zeros((0, self.shape[1]))
        r0, r1 = i // 3, -(-j // 3)  # the readings the rows belong to
        return _axis_blocks(self.block[r0:r1])[i - 3 * r0 : j - 3 * r0]

    def _rows_at(self, idx: np.ndarray) -> np.ndarray:
        idx = np.where(idx < 0, idx + self.shape[0], idx)
        k = self.block.shape[1]
        out = np.zeros((idx.size, self.shape[1]))
        for a in range(3):
            sel = np.flatnonzero(idx % 3 == a)
            out[sel, a * k:(a + 1) * k] = self.block[idx[sel] // 3]
        return out

    def rows_matmul(self, i: int, j: int, C: np.ndarray) -> np.ndarray:
        """``self[i:j] @ C`` (C: (3k,) or (3k × q)) from the block, without the zeros."""
        r0, r1, k = i // 3, -(-j // 3), self.block.shape[1]
        out = np.stack([self.block[r0:r1] @ C[a * k:(a + 1) * k] for a in range(3)], axis=1)
        return out.reshape((3 * (r1 - r0),) + C.shape[1:])[i - 3 * r0:j - 3 * r0]

    def rows_rmatmul(self, i: int, j: int, A: np.ndarray) -> np.ndarray:
        """``self[i:j].T @ A`` (A: the j − i rows) from the block, without the zeros."""
        r0, r1 = i // 3, -(-j // 3)
        pad = np.zeros((3 * (r1 - r0),) + A.shape[1:])
        pad[i - 3 * r0:j - 3 * r0] = A
        pad = pad.reshape((r1 - r0, 3) + A.shape[1:])
        return np.concatenate([self.block[r0:r1].T @ pad[:, a] for a in range(3)])

    def __matmul__(self, beta: np.ndarray) -> np.ndarray:
        beta = np.asarray(beta, float)
        k = self.block.shape[1]
        parts = [self.block @ beta[a * k:(a + 1) * k] for a in range(3)]
        return np.stack(parts, axis=1).reshape((self.shape[0],) + beta.shape[1:])

    def __array__(self, dtype: object = None, copy: object = None) -> np.ndarray:
        dense = _axis_blocks(self.block)
        return dense if dtype is None else dense.astype(dtype)

    def __mul__(self, other: object) -> np.ndarray:
        return np.asarray(self) * other


JOINT_FIT_MAX_ROWS = 50_000  # readings the joint SFEM-cubic fit of the remainder uses


def _joint_fit_rows(n: int) -> slice | np.ndarray:
    """Readings for the joint fit behind the SFEM remainder: all, or a fixed random subset.

    Why: ``fit_joint``'s Jacobian and rotations are ~6 kB per reading at their peak, which set
    diagnose's peak on a long recording (300 k readings: 2.3 GB of 3.0). The fit has 12×(d+1)
    coefficients, and the remainder it predicts is a few µg; 50 000 readings fix them far
    below the noise. Random, not every k-th reading: a stride can alias with the schedule's
    period (every 24th reading of a tiled Table 1 is one position). Seeded: reproducible.
    """
    if n <= JOINT_FIT_MAX_ROWS:
        return slice(None)
    return np.sort(np.random.default_rng(0).choice(n, JOINT_FIT_MAX_ROWS, replace=False))


def _sfem_remainder(raw: np.ndarray, ref: np.ndarray, sig: np.ndarray, t: np.ndarray,
                    degree: int, ctx: DesignContext, beta: np.ndarray, X0: np.ndarray,
                    w: np.ndarray) -> np.ndarray | None:
    """What the SFEM-cubic predicts beyond the linear design's span, at its own fit (N,3) g.

    Why: ``raw = A(T)⁻¹ref + b(T)`` with cubic SFEM parameters is *not* exactly cubic
    in T (A⁻¹ has higher powers); the rest reaches a few µg at the ends of the range,
    is position dependent and would be read by the effect tests (e.g. as an early-plateau
    lag). The base model is the SFEM-cubic, so its remainder is removed from the data:
    a joint fit of the 12×(d+1) coefficients (``thermal_joint.fit_joint``), started from
    the linear fit, and the part of its prediction the linear design cannot represent is
    subtracted. The linear design then carries the SFEM's tangent space as before.
    None when there is nothing to correct (d = 0) or the fit fails.
    """
    if degree == 0:
        return None
    from calibration.fit import _decompose_batch
    from calibration.thermal_joint import fit_joint

    n = raw.shape[0]
    try:
        ids = ctx.step_ids
        ts = np.array([float(np.median(t[ctx.steps == s_])) for s_ in ids])
        Pt = np.column_stack([ts**p for p in range(degree + 1)])
        Ps = np.empty((len(ids), 12))
        coef = beta.reshape(3, 4, degree + 1)  # [axis, (1, ref_x, ref_y, ref_z), power]
        G = np.einsum("ajp,sp->saj", coef[:, 1:, :], Pt)  # raw = G ref + b at each step
        b = np.einsum("ap,sp->sa", coef[:, 0, :], Pt)
        A = np.linalg.inv(G)
        if np.any(np.linalg.det(A) <= 0):
            return None
        Ps[:] = _decompose_batch(A, b)
        cnt = np.array([np.sum(ctx.steps == s_) for s_ in ids], float)
        coeffs0 = np.linalg.lstsq(Pt * np.sqrt(cnt)[:, None], Ps * np.sqrt(cnt)[:, None],
                                  rcond=None)[0].T  # (12, d+1)
        fit = _joint_fit_rows(n)
        res = fit_joint(raw[fit], ref[fit], sig[fit], t[fit], coeffs0, np.ones(12, bool))
        V = np.vander(t, degree + 1, increasing=True)
        Pn = V @ res.coeffs.T
        pred = sfem.inverse(Pn, ref)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(pred)):
        return None
    lin = _wls(X0, w, pred.ravel())
    rem = pred - (X0 @ lin).reshape(n, 3)
    return rem


def _norm_problem(rec: Recording, capture_means: bool = False) -> LinearProblem:
    raw = rec.raw_g
    n = raw.shape[0]
    start = sfem_fit.fit_norm(raw, rec.sigma_g)
    free = sfem_fit.NORM_FREE
    ctx0 = base_context(rec, "norm", raw)
    P, degree, mid, half = _powers(ctx0.temp_c, ctx0.steps)
    npow = P.shape[1]
    fixed = start.params.to_vector()
    coeffs0 = np.zeros((sfem.N_PARAMS, npow))
    coeffs0[:, 0] = fixed

    def params(qq: np.ndarray) -> np.ndarray:
        Pm = np.tile(fixed, (n, 1))
        Pm[:, free] = P @ qq.T
        return Pm

    # the joint SFEM fit (thermal_joint: the 9×(d+1) coefficients, equal weights, |f| − 1)
    # started at the pooled fit
    from calibration.thermal_joint import fit_joint

    x = P[:, 1] if npow > 1 else np.zeros(n)
    q = fit_joint(raw, None, np.ones((n, 3)), x, coeffs0, free).coeffs[free]
    Pm = params(q)
    f, jac = sfem.forward_jacobian(Pm, raw)
    nf = np.linalg.norm(f, axis=1)
    uvec = f / nf[:, None]
    A = sfem.matrix_from_vector(Pm)
    gvec = np.einsum("ni,nij->nj", uvec, A)  # ∂|f|/∂raw
    X0 = sfem.coefficient_jacobian(sfem.norm_jacobian(f, jac[:, :, free]), P)
    y = nf - 1.0
    ctx = base_context(rec, "norm", f)
    sig = pooled_sigma_g(rec, ctx.steps)
    from_sd = sig is not None and bool(np.all(np.isfinite(sig) & (sig > 0)))
    tau = kappa = None
    if from_sd:
        s_norm = np.sqrt(np.sum((gvec * sig) ** 2, axis=1))
        if capture_means:
            beta = np.linalg.lstsq(X0 / s_norm[:, None], y / s_norm, rcond=None)[0]
            e = y - X0 @ beta
            corr = float(np.sqrt(n / max(n - X0.shape[1], 1)))
            s2, kappa, tau = capture_noise(e[:, None], s_norm[:, None], corr)
            s_norm = s2[:, 0]
    else:
        beta = np.linalg.lstsq(X0, y, rcond=None)[0]
        e = y - X0 @ beta
        corr = np.sqrt(n / max(n - X0.shape[1], 1))
        s_norm = np.full(n, max(1.4826 * np.median(np.abs(e - np.median(e))) * corr, 1e-9))
    if degree > 0:
        h = 0.01 * half
        Pm_h = np.tile(fixed, (n, 1))
        th = (ctx0.temp_c + h - mid) / half
        Pm_h[:, free] = np.column_stack([th**p for p in range(npow)]) @ q.T
        raw_h = sfem.inverse(Pm_h, f)
        raw_0 = sfem.inverse(Pm, f)
        ctx.draw_dtemp_g_per_c = (raw_h - raw_0) / h

        def temperature_shift(dT_c: np.ndarray) -> np.ndarray:
            """The base's raw output at T + dT minus at T, for the same calibrated output."""
            Pm_d = np.tile(fixed, (n, 1))
            td = (ctx0.temp_c + dT_c - mid) / half
            Pm_d[:, free] = np.column_stack([td**p for p in range(npow)]) @ q.T
            return sfem.inverse(Pm_d, f) - raw_0

        ctx.temperature_shift = temperature_shift
        sig_T = temperature_noise_c(ctx)
        if from_sd and np.any(sig_T > 0):
            # As in reference mode: the recorded temperature's noise moves |f| along
            # ∂|f|/∂T (at fixed raw). Without it a 0.1 °C channel on a sensor with a
            # typical tempco reads as structure (issue 10: ~¼ of nulls flagged).
            dnorm_dT = (np.linalg.norm(sfem.forward(Pm_h, raw), axis=1) - nf) / h
            s_norm = np.sqrt(s_norm**2 + (dnorm_dT * sig_T) ** 2)

    def lift(x: np.ndarray) -> np.ndarray:
        return np.einsum("na,nak->nk", gvec, x.reshape(n, 3, -1))

    def lift_rows(rows: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return rows, np.einsum("na,nak->nk", gvec[rows], x.reshape(rows.size, 3, -1))

    return LinearProblem(
        "norm", y, X0, 1.0 / s_norm, np.arange(n), np.full(n, -1), lift, ctx, from_sd,
        degree, mid, half, lift_rows, None, tau, kappa,
    )
