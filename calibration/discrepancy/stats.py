"""Statistics after projecting out the current model, and their parametric-bootstrap null.

Given the whitened design X of the current model (base + accepted terms), every
statistic is a function of the residual ``e = (I − P_X) y``. Under the null
(base model + Gaussian noise, the parametric bootstrap of docs/diagnosis.md §2)
``e = (I − P_X) ε`` for any β, so a null replicate is one projection of
white noise: the projections are data-independent given the design, and B
replicates cost a few matrix products. The families with columns and the scan take sign
flips of the recording's own residual instead (:func:`wild_replicates`): its noise is not
the model's white noise (re-seating, vibration).

Statistics are normalised by a noise scale of the same residual (F-type: the
residual after the candidate; outliers: a robust MAD scale), so they are
scale-free: the null does not depend on the noise level, and an underestimated
sd/√n cannot cause false alarms. p-values are kept as logs (strong effects are
far below 1e-300).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats as sps
from scipy.special import betaln, gammaln

ABSORBED_MAX = 0.99  # beyond this the base model swallows the effect: not identifiable here


TALL_BYTES = 64 * 2**20  # above this a tall design's basis comes from its Gram matrix


def orthonormal_basis(X: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the column space of X (SVD; rank-deficient columns dropped).

    A tall X larger than :data:`TALL_BYTES` takes :func:`orthonormal_basis_tall`: the SVD
    holds ~3.6 copies of X at its peak (measured, m = 300 000 × 48), the Gram route one.
    """
    if X.shape[1] == 0:
        return np.zeros((X.shape[0], 0))
    if is_tall(*X.shape):
        return orthonormal_basis_tall(X)
    U, s, _ = np.linalg.svd(X, full_matrices=False)
    keep = s > rel_tol * max(float(s[0]), 1e-300)
    return U[:, keep]


GRAM_REL_TOL = 1e-12  # eigenvalue cut of the scaled Gram (singular-value ratio 1e-6)


def orthonormal_basis_tall(X: np.ndarray) -> np.ndarray:
    """Orthonormal basis of a tall X from its Gram matrix, then one re-orthonormalisation.

    Columns scaled to unit norm, G = XᵀX eigendecomposed (p × p), directions with
    λ ≤ 1e-12·λmax dropped (the Gram resolves singular-value ratios to ~1e-8 only, so the
    cut is coarser than the SVD's 1e-9; such near-collinear directions carry no
    testable signal), U₁ = X V Λ^-½ by row blocks, then U = U₁ R⁻¹ with RᵀR = U₁ᵀU₁
    (Cholesky-QR2: orthonormal to rounding when the scaled design's condition is far
    below 1e8, as the base design's is). One (m × r) array besides X.
    """
    return orthonormal_basis_of_blocks(lambda i, j: X[i:j], X.shape[0], X.shape[1], X.T @ X)


def eigen_cut_map(gram: np.ndarray) -> np.ndarray:
    """(p × r) T such that X·T spans X's column space with near-orthonormal columns, from
    the Gram matrix ``XᵀX`` alone: its columns scaled to unit norm, eigenvalues below
    ``GRAM_REL_TOL`` of the largest cut (the rank decision), the rest whitened. The first
    half of Cholesky-QR2; the caller finishes with the Cholesky factor of ``(X·T)ᵀ(X·T)``.
    """
    d = np.sqrt(np.diag(gram))
    inv = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0)
    lam, V = np.linalg.eigh(gram * inv[:, None] * inv[None, :])
    keep = lam > GRAM_REL_TOL * max(float(lam.max()), 1e-300)
    return (inv[:, None] * V[:, keep]) / np.sqrt(lam[keep])


def orthonormal_basis_of_blocks(
    rows: Callable[[int, int], np.ndarray], m: int, p: int, gram: np.ndarray | None = None
) -> np.ndarray:
    """:func:`orthonormal_basis_tall` of an (m × p) X given by its row blocks ``rows(i, j)``.

    Why: the design of a long recording need not exist whole (issue 10: at 1 M readings the
    whitened design is 1.15 GB next to the base design and the basis). ``gram`` (XᵀX) when
    the caller has it; else it is summed over the blocks.
    """
    if gram is None:
        gram = np.zeros((p, p))
        for sl in row_blocks(m, p):
            B = rows(sl.start, sl.stop)
            gram += B.T @ B
    T = eigen_cut_map(gram)
    U = np.empty((m, T.shape[1]))
    for sl in row_blocks(m, p):
        U[sl] = rows(sl.start, sl.stop) @ T
    R = np.linalg.cholesky(U.T @ U).T  # upper: U₁ = U R
    Rinv = np.linalg.inv(R)
    for sl in row_blocks(m, p):
        U[sl] = U[sl] @ Rinv
    return U


def project_out(U: np.ndarray, X: np.ndarray) -> np.ndarray:
    return X - U @ (U.T @ X)


CHUNK_BYTES = 16 * 2**20  # working block of the null replicates' row/column loops


def row_blocks(m: int, width: int, start: int = 0) -> Iterator[slice]:
    """Slices of the rows ``start`` … ``m``, each a working block (CHUNK_BYTES) of an array
    ``width`` float64 wide. Every row loop over the diagnosis' large arrays goes by these
    blocks (issue 10, memory): a product with an (m × B) array is formed one block at a
    time, so no second (m × B) array exists."""
    step = max(1, CHUNK_BYTES // (8 * max(width, 1)))
    for i in range(start, m, step):
        yield slice(i, min(i + step, m))


def t_matmul(A: Any, E: np.ndarray) -> np.ndarray:
    """``Aᵀ·E`` for an (m × k) or (m,) ``A`` (an array or a basis.RowBlockBasis) and
    replicates ``E`` (m × B) of either float width, in double precision.

    Why (issue 22, memory): replicates beyond the null budget are stored in single precision
    (:func:`replicate_dtype`); numpy's product of a double and a single array first casts the
    whole single one, a double (m × B) copy (480 MB at 1 M readings). Here a single ``E`` is
    cast one row block at a time; a double one takes numpy's product as before.
    """
    if E.dtype == np.float64 or not isinstance(A, np.ndarray):
        return A.T @ E  # a RowBlockBasis casts by its own row blocks (basis.rmatmul_t)
    out = np.zeros(A.shape[1:] + E.shape[1:])
    for sl in row_blocks(E.shape[0], int(np.prod(A.shape[1:])) + E.shape[1]):
        out += A[sl].T @ E[sl].astype(np.float64)
    return out


def replicate_dtype(m: int, n_null: int, budget_bytes: int) -> type[np.floating]:
    """The width the (m × n_null) replicates are stored in: double within ``budget_bytes``,
    single beyond it.

    Why (issue 22, memory): at 1 M readings the null is cut to its 20-replicate floor and
    is still 480 MB in double, the largest array of ``diagnose`` (its peak 2.1× calibrate's).
    A replicate is unit-variance noise; single precision rounds it at 6e-8, which moves no
    F statistic nor reading statistic beyond the 7th digit (they are formed and summed in
    double: :func:`t_matmul`, :func:`sum_sq_columns`). Recordings within the budget keep
    double replicates, so their diagnoses are unchanged to the bit.
    """
    return np.float64 if 8 * m * n_null <= budget_bytes else np.float32


def project_out_inplace(U: np.ndarray, E: np.ndarray) -> np.ndarray:
    """``E ← (I − UUᵀ)E`` by blocks of rows: no second (m × B) array (issue 10, memory).

    ``UᵀE`` is (p × B), small; the product ``U·(UᵀE)`` is formed one row block at a time.
    """
    UtE = t_matmul(U, E)
    for sl in row_blocks(E.shape[0], E.shape[1]):
        E[sl] -= U[sl] @ UtE
    return E


def null_replicates(
    rng: np.random.Generator, m: int, n_null: int, row: np.ndarray,
    shared: np.ndarray | None = None, dtype: type[np.floating] = np.float64,
) -> np.ndarray:
    """(m × B) whitened noise of the parametric bootstrap (docs/diagnosis.md §2).

    Entries are unit-variance. ``shared`` (m,): each entry's loading c on one N(0,1) draw
    per reading (``row``), the recorded temperature's error that moves a reading's three
    axes together: entry = √(1 − c²)·z + c·ξ_row, so the null has the data's within-reading
    correlation. Without ``shared`` it is white noise, drawn exactly as before. ``dtype``
    (:func:`replicate_dtype`): single precision is filled by row blocks of double draws,
    the same numbers in the same order as the one draw, rounded.
    """
    if dtype == np.float64:
        E = rng.standard_normal((m, n_null))
    else:
        E = np.empty((m, n_null), dtype)
        for sl in row_blocks(m, n_null):  # the generator's stream consumed as by the one draw
            E[sl] = rng.standard_normal((sl.stop - sl.start, n_null))
    if shared is None:
        return E
    xi = rng.standard_normal((int(row.max()) + 1, n_null))
    c = np.clip(shared, -1.0, 1.0)
    own = np.sqrt(1.0 - c**2)
    for sl in row_blocks(m, n_null):  # by row blocks: no second (m × B) array
        E[sl] *= own[sl, None]
        E[sl] += c[sl, None] * xi[row[sl]]
    return E


LEVERAGE_MAX = 0.95  # a residual entry with leverage above this is rescaled as if at it


def leverage(U: np.ndarray) -> np.ndarray:
    """(m,) leverage h = ‖U_i‖² of each whitened entry (U orthonormal), by row blocks."""
    h = np.empty(U.shape[0])
    for sl in row_blocks(U.shape[0], U.shape[1]):
        b = np.asarray(U[sl])
        h[sl] = np.einsum("ij,ij->i", b, b)
    return h


def leave_entries_out(U: Any, e: np.ndarray, h: np.ndarray, entries: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Residual and leverage of the other entries when ``entries`` are fitted by their own
    columns (a unit vector each): the model refitted without them, in closed form.

    Adding the columns I_J to an orthonormal basis U (residual e ⊥ U): with Z = (I − P)I_J
    and M = ZᵀZ = I − U_J U_Jᵀ, the residual is e − Z M⁺ e_J (Zᵀe = e_J) and the leverage of
    an entry i outside J grows by U_i A U_iᵀ, A = U_Jᵀ M⁺ U_J (p × p); the entries of J are
    returned with residual 0 and leverage 1. U by row blocks (a RowBlockBasis is not made
    dense). Why (issue 22): a reading far off pulls the fit, and on a few readings per
    column (4 plateaus of 12 positions) that pull puts a share of its
    deviation into its plateau's and its position's other readings; their entries were
    then the heavy tail the outlier's null was drawn with.
    """
    J = np.asarray(entries, int)
    e_out, h_out = np.array(e, float), np.array(h, float)
    if J.size == 0:
        return e_out, h_out
    UJ = np.asarray(U[J], float)  # (q × p)
    Minv = np.linalg.pinv(np.eye(J.size) - UJ @ UJ.T, rcond=1e-9, hermitian=True)
    c = Minv @ np.asarray(e, float)[J]
    A = UJ.T @ Minv @ UJ
    v = UJ.T @ c
    for sl in row_blocks(e_out.size, UJ.shape[1]):
        b = np.asarray(U[sl])
        e_out[sl] += b @ v
        h_out[sl] += np.einsum("ij,jk,ik->i", b, A, b)
    e_out[J], h_out[J] = 0.0, 1.0
    return e_out, h_out


def reading_cap(r: np.ndarray, row: np.ndarray,
                plateaus: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(N,) factor ≤ 1 per reading that caps its residual vector's size at the largest a
    Gaussian reading of this recording reaches: ‖r_g‖²/s² ≤ χ²_g's 1 − 1/(2N) quantile,
    s the MAD scale of all entries.

    Why: under an effect the residual holds its structure, and sign flips of a reading
    that carries a strong localised part (a jump after one plateau, a rate on the first
    ones) put that reading's size into every replicate: the F tests' null became as heavy
    as the data (a jump at p = 1e-17 scored p_family = 0.01). Capped, such a reading keeps
    its direction and counts as the largest noise reading would; under the null the cap
    touches about one reading in 2N.

    ``plateaus`` (each reading's plateau (N,), each entry's axis (m,);
    plateau_noise.cap_cells): s is each plateau's own scatter where it is larger than all
    entries' — the MAD of its entries' deviations from their plateau × axis median, so an
    offset of a plateau (what the families test) does not loosen its cap. Why (issue 22):
    where a plateau's stated noise is far above its scatter (a vibration whose mean
    averages down faster than white, the third generator's nulls) and another's is not,
    the whitened entries of the second are several times the first's; the global s sat at
    the first's level and the second's readings were capped in the replicates and not in
    the data, and the scan and the family test fired on null recordings.
    """
    n = int(row.max()) + 1
    g = max(int(np.bincount(row).max()), 1)
    s = float(robust_scale(r[:, None], 1.0)[0])
    s_read = np.full(n, max(s, 1e-300))
    if plateaus is not None:
        plateau, axis = plateaus
        for k in np.unique(plateau):
            idx = np.flatnonzero((plateau == k)[row])  # the plateau's entries
            dev = r[idx]
            ax = axis[idx]
            for a in np.unique(ax):
                dev[ax == a] -= np.median(dev[ax == a])
            s_k = 1.4826 * float(np.median(np.abs(dev)))
            if s_k > s:
                s_read[plateau == k] = s_k
    size2 = np.bincount(row, r**2, minlength=n) / s_read**2
    cap2 = float(sps.chi2.isf(1.0 / (2 * n), g))
    with np.errstate(divide="ignore"):
        return np.where(size2 > cap2, np.sqrt(cap2 / np.maximum(size2, 1e-300)), 1.0)


def wild_replicates(
    rng: np.random.Generator, e: np.ndarray, U: np.ndarray, row: np.ndarray, out: np.ndarray,
    leave_out: tuple[int, ...] = (),
    shared: tuple[SharedGroups, np.ndarray, float] | None = None,
    known: tuple[SharedGroups, np.ndarray] | None = None,
    plateaus: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Sign-flip (wild) replicates of the whitened residual ``e``, one sign per reading,
    written into ``out`` (m × B) and projected off ``U``: ``(I − P)(r_row ⊙ e/√(1 − h))``.

    Why (issue 22): the Gaussian replicates have the noise *model*'s covariance, unit and
    white apart from the temperature loading. A real recording's whitened noise is not: a
    re-seating error is a small rotation per visit (scatter across the reference, none
    along it), slow vibration scales a capture's three axes together, a plateau's σ is
    estimated from a few readings. The F tests of smooth columns (a drift, a hysteresis,
    the pose turns) and the scan's local blocks then ran above their level on the second
    generator's nulls (per-candidate p ≤ 0.01 in 3–5 % of them). A sign per reading keeps
    each reading's own residual vector, so its size, its direction and the correlation of
    its axes are the recording's; the signs make it a null (no structure shared between
    readings). ``1/√(1 − h)`` undoes the shrinkage of a fitted residual (HC2). Not for the
    outlier family: its statistic is a reading's own size, which a sign does not change.
    ``leave_out``: readings drawn as zero, the outlier family's candidate reading: one
    reading far out is that family's question, and with random signs it would make every
    other family's null heavier by its size (a true outlier then lost its own test to
    them in the min over families).
    ``shared`` (groups, θ, s²) from :func:`shared_variance`: the noise the readings of a
    plateau share, which the per-reading signs remove, is drawn back in as Gaussian
    offsets per group (:func:`add_shared`) before the projection, and the signs flip each
    entry's deviation from its group's mean (:func:`within_groups`): flipped with them, the
    data's group offsets came back as extra white noise, the F tests' denominators grew and
    the null ran light (at a 5 % level 12 % with the true θ).
    ``known`` (groups, variances): shared noise whose variance is known rather than fitted
    (a non-dithering quantised temperature channel, plateau_noise.quantised_channel), drawn
    in the same way (variances in the loadings' units); the data's residual is flipped as
    it is, since no variance is read from it.
    ``plateaus``: each reading's plateau and each entry's axis, for the reading cap at each
    plateau's own scatter (:func:`reading_cap`).
    """
    if shared is not None:
        e = within_groups(e, shared[0])
    scale = e / np.sqrt(1.0 - np.minimum(leverage(U), LEVERAGE_MAX))
    if leave_out:
        scale[np.isin(row, leave_out)] = 0.0
    scale *= reading_cap(scale, row, plateaus)[row]
    n, b = int(row.max()) + 1, out.shape[1]
    if np.all(row[1:] >= row[:-1]):  # entries by reading (every problem's layout)
        # Each block of readings' signs drawn as it is used: the (N × B) signs were 160 MB
        # beside the replicates at 1 M readings (issue 22, memory); the same draws in the
        # same order (reading_signs), so the same replicates and the generator's state.
        for r0, signs in sign_blocks(rng, n, b):
            i, j = np.searchsorted(row, [r0, r0 + signs.shape[0]])
            for sl in row_blocks(j, b, start=i):  # by row blocks: no second (m × B) array
                np.multiply(scale[sl, None], signs[row[sl] - r0], out=out[sl])
    else:
        signs = reading_signs(rng, n, b)
        for sl in row_blocks(out.shape[0], b):  # by row blocks: no second (m × B) array
            np.multiply(scale[sl, None], signs[row[sl]], out=out[sl])
    if shared is not None:
        add_shared(rng, shared[0], shared[1], shared[2], out)
    if known is not None:
        add_shared(rng, known[0], known[1], 1.0, out)
    return project_out_inplace(U, out)


def reading_signs(rng: np.random.Generator, n: int, b: int) -> np.ndarray:
    """(n × b) signs ±1.0, one per reading and replicate: ``rng.integers(0, 2, (n, b))``
    mapped to ±1, drawn by blocks of readings in the same order (the generator's stream is
    consumed as by the one draw). Why (issue 22, memory): the one draw and its float copies
    were two (n × b) arrays at once (320 MB at 1 M readings and 20 replicates)."""
    out = np.empty((n, b))
    for i, block in sign_blocks(rng, n, b):
        out[i : i + block.shape[0]] = block
    return out


def sign_blocks(rng: np.random.Generator, n: int, b: int) -> Iterator[tuple[int, np.ndarray]]:
    """The signs of :func:`reading_signs` block by block: (first reading, (r × b) signs),
    about CHUNK_BYTES each, in reading order; the generator consumed as by the one draw."""
    for sl in row_blocks(n, b):
        block = np.empty((sl.stop - sl.start, b))
        np.multiply(rng.integers(0, 2, block.shape), 2.0, out=block)
        block -= 1.0
        yield sl.start, block


# Tail of the per-reading statistic (reading_tail_dof): the order statistics at the median
# and near TAIL_P_HI, their levels counted as if the TAIL_OUTLIERS largest readings were
# outliers (not noise) and never above them, compared with χ²_g's; a finite ν only when the
# ratio exceeds χ²_g's by TAIL_Z standard errors; ν no lower than TAIL_DOF_MIN (finite
# kurtosis); at least TAIL_MIN_READINGS readings (fewer cannot show a tail).
TAIL_P_LO, TAIL_P_HI = 0.5, 0.95
# Three candidates (issue 22): a transient (a snag, a knock) can disturb a few captures, and
# with two left out a third reading far off among 90 was the tail its own null was read from.
TAIL_OUTLIERS = 3
TAIL_Z = 2.0
# The outlier test's null (diagnose._reading_dof, from the entries: entry_tail_dof) reads
# ν at its point estimate: the Student-t mixture wherever the ratio exceeds the Gaussian's
# at all, not only by TAIL_Z standard errors (a margin of ∞ keeps the Gaussian null).
# Why (issue 22): capture means of a real sensor are mildly heavy-tailed (per
# reading about a Student-t mixture with ν ≈ 40 on the second generator's nulls: the
# per-reading statistic's tail 1.3×, 2.7× and 5× χ²_3's at its 95 %, 99.9 % and 99.99 %
# points), which 100–300 readings cannot show at 2 standard errors; against the Gaussian
# null the max over readings was at its 5 % level in 15 % of those nulls and made half of
# the verdict's false alarms (docs/benchmarks.md, "False alarms of the second generator's
# nulls, test by test").
NULL_TAIL_Z = 0.0
TAIL_DOF_MIN = 5.0
TAIL_DOF_MAX = 1e4
TAIL_MIN_READINGS = 20


def reading_tail_dof(t_row: np.ndarray, g: int, z_se: float | None = None) -> float:
    """ν of the Student-t scale mixture the recording's per-reading statistics show (∞: none).

    ``t_row``: the leave-one-reading-out statistics (:func:`row_stats`, χ²_g under a Gaussian
    null) of the readings not already excluded. Under a per-reading scale mixture (a
    capture's vibration or settling moves its three axes' scatter together) the statistic
    is g·F(g, ν), whose quantile ratio Q(0.95)/Q(0.5) decreases to χ²_g's as ν → ∞. The
    data's ratio is read from order statistics that exclude the largest readings, so one
    or two outliers — the candidates the test is about — cannot raise it (a kurtosis would
    be dominated by them). A finite ν is returned only when the ratio exceeds χ²_g's by
    :data:`TAIL_Z` standard errors of the sample quantiles (asymptotic order-statistic
    covariance), so Gaussian recordings keep the Gaussian null; it is floored at
    :data:`TAIL_DOF_MIN`. ``z_se``: that margin in standard errors (default
    :data:`TAIL_Z`); 0 gives the point estimate (the outlier test's null,
    :data:`NULL_TAIL_Z`): a ratio above χ²_g's by less than its noise then gives a large ν.
    """
    t = np.sort(np.asarray(t_row, float)[np.isfinite(t_row)])
    n = t.size
    if n < TAIL_MIN_READINGS or g < 1:
        return np.inf
    # The r-th largest reading, r ≥ k + 2: with up to k outliers on top it is still a noise
    # reading, at level 1 − (r − k − ½)/(n − k) of the n − k noise readings (on a clean
    # recording it lies lower: the test then leans to the Gaussian null, never away from it).
    k = TAIL_OUTLIERS
    r = max(k + 2, int(np.ceil((1 - TAIL_P_HI) * n)))
    p_lo, p_hi = TAIL_P_LO, 1 - (r - k - 0.5) / (n - k)
    q_lo, q_hi = t[int(np.ceil(p_lo * n)) - 1], t[n - r]
    if q_lo <= 0:
        return np.inf
    log_r = float(np.log(q_hi / q_lo))
    c_lo, c_hi = sps.chi2.ppf([p_lo, p_hi], g)
    f_lo, f_hi = sps.chi2.pdf([c_lo, c_hi], g)
    # var(log Q_p) ≈ p(1 − p) / (n (f q)²); cov for p1 < p2: p1(1 − p2) / (n f1 q1 f2 q2)
    a_lo, a_hi = 1.0 / (f_lo * c_lo), 1.0 / (f_hi * c_hi)
    var = (p_lo * (1 - p_lo) * a_lo**2 + p_hi * (1 - p_hi) * a_hi**2
           - 2 * p_lo * (1 - p_hi) * a_lo * a_hi) / n
    log_r_gauss = float(np.log(c_hi / c_lo))
    if log_r <= log_r_gauss + (TAIL_Z if z_se is None else z_se) * np.sqrt(var):
        return np.inf

    def excess(nu: float) -> float:
        lo, hi = sps.f.ppf([p_lo, p_hi], g, nu)
        return float(np.log(hi / lo)) - log_r

    if excess(TAIL_DOF_MIN) <= 0:
        return TAIL_DOF_MIN
    if excess(TAIL_DOF_MAX) >= 0:
        return np.inf
    from scipy.optimize import brentq

    return float(brentq(excess, TAIL_DOF_MIN, TAIL_DOF_MAX, xtol=1e-3))


# The outlier test's null reads ν from the readings' entries (entry_tail_dof): the
# order statistic of |z| near ENTRY_P_HI against the median, both over the entries of the
# readings that are not the TAIL_OUTLIERS largest, compared with Student-t's.
ENTRY_P_HI = 0.99
ENTRY_MIN_RANK = 3


def entry_tail_dof(z: np.ndarray, z_se: float | None = None) -> float:
    """ν of the Student-t the whitened residual's entries show (∞: none), from the ratio of
    |z|'s order statistic near :data:`ENTRY_P_HI` to its median.

    ``z``: the entries (each over its own standard deviation) of the readings the test does
    not hold as candidates (the :data:`TAIL_OUTLIERS` largest readings' entries left out,
    as :func:`reading_tail_dof` leaves them). Why not the per-reading statistic: a capture
    mean's error heavy-tailed on each axis (a Student-t per axis, issue 22's third
    generator) shows in a reading's statistic only where one axis dominates it; summed with
    the reading's other, Gaussian-like axes, the statistic's 95th percentile is nearly
    χ²_g's, and the tail shows only in its top few readings (the candidates themselves).
    Per entry, three times as many values carry that tail, undiluted, and its 99th
    percentile against the median already sets it apart from Gaussian's on 100–300
    readings. The ν so read goes to the per-reading Student-t mixture of the null
    (:func:`row_stats`), which at the same ν has the heavier tail of the two laws.

    ``z_se``: the margin, in standard errors of the log ratio (asymptotic order-statistic
    covariance), by which the ratio must exceed the Gaussian's for a finite ν, as in
    :func:`reading_tail_dof` (default :data:`TAIL_Z`: a resolved tail; the outlier null
    takes :data:`NULL_TAIL_Z`, 0: the point estimate; ∞: always the Gaussian).
    """
    a = np.sort(np.abs(np.asarray(z, float)[np.isfinite(z)]))
    m = a.size
    if m < TAIL_MIN_READINGS:
        return np.inf
    r = max(ENTRY_MIN_RANK, int(np.ceil((1 - ENTRY_P_HI) * m)))
    p_hi = 1 - (r - 0.5) / m
    q_lo, q_hi = float(np.median(a)), float(a[m - r])
    if q_lo <= 0:
        return np.inf
    log_r = float(np.log(q_hi / q_lo))
    u = (1 + p_hi) / 2  # |z| at p_hi is the (1 + p_hi)/2 point of z
    c_lo, c_hi = sps.norm.ppf([0.75, u])
    # var(log Q_p) ≈ p(1 − p) / (m (f q)²), cov for p1 < p2: p1(1 − p2) / (m f1 q1 f2 q2),
    # f = 2φ the density of |z|
    a_lo, a_hi = 1.0 / (2 * sps.norm.pdf(c_lo) * c_lo), 1.0 / (2 * sps.norm.pdf(c_hi) * c_hi)
    var = (0.25 * a_lo**2 + p_hi * (1 - p_hi) * a_hi**2 - 2 * 0.5 * (1 - p_hi) * a_lo * a_hi) / m
    if log_r <= float(np.log(c_hi / c_lo)) + (TAIL_Z if z_se is None else z_se) * np.sqrt(var):
        return np.inf

    def excess(nu: float) -> float:
        return float(np.log(sps.t.ppf(u, nu) / sps.t.ppf(0.75, nu))) - log_r

    if excess(TAIL_DOF_MIN) <= 0:
        return TAIL_DOF_MIN
    if excess(TAIL_DOF_MAX) >= 0:
        return np.inf
    from scipy.optimize import brentq

    return float(brentq(excess, TAIL_DOF_MIN, TAIL_DOF_MAX, xtol=1e-3))


def tail_scale(nu: float) -> float:
    """(MAD of t_ν / MAD of N(0,1))²: the Student-t mixture's entries against a MAD scale.

    The statistics divide by a MAD scale s²; a reading drawn from the mixture √w·z with
    w ~ ν/χ²_ν has entries t_ν, whose MAD exceeds the Gaussian's by this factor's root.
    """
    return 1.0 if not np.isfinite(nu) else float((sps.t.ppf(0.75, nu) / sps.norm.ppf(0.75))**2)


def reading_logsf(t: np.ndarray | float, g: int, nu: float = np.inf) -> np.ndarray:
    """log P(statistic > t) of a per-reading statistic: χ²_g, or under the Student-t
    mixture with ν (:func:`entry_tail_dof`, as diagnose reads it) g·F(g, ν) on the MAD-scaled
    statistic."""
    if not np.isfinite(nu):
        return chi2_logsf(t, g)
    x = np.maximum(np.asarray(t, float), 0.0) * tail_scale(nu) / g
    with np.errstate(divide="ignore"):
        v = sps.f.logsf(x, g, nu)
    return np.where(np.isfinite(v), v, chi2_logsf(t, g))


def _residual_cov_blocks(
    U: np.ndarray, Ug: np.ndarray, c: np.ndarray, idx: np.ndarray
) -> np.ndarray:
    """(N, g, g) blocks of Cov(e) = (I − P) C (I − P), C block-diagonal per reading.

    C = diag(1 − c²) + per-reading c cᵀ (unit diagonal). With P = UUᵀ and C block-diagonal,
    the g-block is C_g − U_gU_gᵀC_g − C_gU_gU_gᵀ + U_g (UᵀCU) U_gᵀ, where
    UᵀCU = I − Uᵀdiag(c²)U + Σ_readings v vᵀ, v = U_gᵀc_g (p × p, accumulated by blocks).
    """
    n, g, p = Ug.shape
    cg = c[idx]  # (N, g)

    def c_blocks(sl: slice) -> np.ndarray:  # C_g of the readings sl (not all N at once)
        cb = cg[sl]
        return np.eye(g)[None] * (1.0 - cb[:, :, None] ** 2) + cb[:, :, None] * cb[:, None, :]

    W = np.eye(p)
    for sl in row_blocks(n, g * max(p, 1)):  # v by blocks of readings: no (N × p) array
        V = np.einsum("ng,ngp->np", cg[sl], Ug[sl])
        W += V.T @ V
    c2 = c**2
    for sl in row_blocks(U.shape[0], p):
        Ub = U[sl]
        W -= (Ub * c2[sl, None]).T @ Ub
    out = np.empty((n, g, g))
    for sl in row_blocks(n, g * max(p, 1)):  # by readings: U_g W is an (m × p) array at once
        Ub, Cb = Ug[sl], c_blocks(sl)
        UUtC = np.einsum("ngp,nhp->ngh", Ub, Ub) @ Cb
        UWU = np.einsum("ngq,nhq->ngh", Ub @ W, Ub)
        out[sl] = Cb - UUtC - np.transpose(UUtC, (0, 2, 1)) + UWU
    return out


def sum_sq_columns(E: np.ndarray) -> np.ndarray:
    """Σ E² of each column without the (m × B) temporary of ``np.sum(E**2, axis=0)``;
    single-precision replicates summed in double, by row blocks."""
    if E.dtype == np.float64:
        return np.einsum("ij,ij->j", E, E)
    out = np.zeros(E.shape[1])
    for sl in row_blocks(E.shape[0], E.shape[1]):
        b = E[sl].astype(np.float64)
        out += np.einsum("ij,ij->j", b, b)
    return out


def robust_scale(E: np.ndarray, dof_corr: float) -> np.ndarray:
    """MAD scale of residual columns (one per replicate), corrected for the fitted dof.

    By blocks of columns: the median of |E| needs a copy, of one block at a time only.
    """
    med = (
        np.concatenate(
            [np.median(np.abs(E[:, sl]), axis=0) for sl in row_blocks(E.shape[1], E.shape[0])]
        )
        if E.shape[1]
        else np.zeros(0)
    )
    return 1.4826 * med.astype(np.float64) * dof_corr


def absorbed_fraction(U: np.ndarray, X: np.ndarray) -> float:
    """1 − ‖(I−P)X‖²/‖X‖²: how much of an effect the current model already explains."""
    tot = float(np.sum(X**2))
    if tot <= 0:
        return 1.0
    return 1.0 - float(np.sum(project_out(U, X) ** 2)) / tot


@dataclass
class CandidateTest:
    """One effect's test at this stage: statistic on the data and on each null replicate.

    p-values are kept as natural logs: strong effects give p far below 1e-300, and
    ranking candidates by p must not be decided by floating-point underflow.
    """

    effect_id: str
    logp: float  # log p of the best grid value / row (before the multiplicity adjustment)
    multiplicity: int  # grid values or rows the max ran over
    logp_adj: float  # Šidák-adjusted for that multiplicity
    logp_adj_null: np.ndarray  # (B,) the same on the null replicates
    theta: float  # best grid value (nan when linear; the row for outliers)
    absorbed: float
    stat: float
    profile: dict[float, float] = field(default_factory=dict)  # theta → log p
    theta_sd: float = float("nan")  # profile-likelihood sd of a continuous theta

    @property
    def p_adj(self) -> float:
        return float(np.exp(self.logp_adj))


def min_p_family(logp: np.ndarray, logp_null: np.ndarray) -> tuple[float, int]:
    """The family-wise p of a stage's test over k candidate families, each family's nominal
    p first calibrated on its own replicates (the min-P of Westfall & Young 1993, *Resampling-
    Based Multiple Testing*, Wiley). Returns (p_family, index of the leading family).

    ``logp`` (k,): each family's nominal (Šidák-adjusted) log p on the recording;
    ``logp_null`` (k, B): the same on each of the B null replicates. The recording and its
    replicates are B + 1 items, exchangeable under the null. For each family the calibrated
    p of an item is its rank among the B + 1 values, ties counted against it (the number of
    items at or below its log p, itself included) over B + 1; each item's statistic is the
    smallest calibrated p over the families, and p_family = (1 + #{replicates at or below
    the recording})/(B + 1). The map is symmetric in the B + 1 items, so the rank test is
    exact under exchangeability whatever each family's nominal law.

    Why: the minimum over *nominal* p lets the family whose nominal p is least calibrated
    (a sign-flip null whose own replicates reach small p often) set every family's
    threshold: an outlier beyond all 400 of its own replicates (nominal 10⁻⁷·⁰) was judged
    against the pose turns' replicates, 160 of which reach 10⁻⁶·⁹ (p_family 0.45;
    docs/benchmarks.md). Calibrated on its own replicates, each family counts alike.

    Ties between families: at one calibrated level every family has an item (rank 1 is the
    most extreme value of each), so by that level alone a recording beyond all replicates of
    one family ties with the most extreme replicate of each other family and p_family could
    not fall below about k/(B + 1) (10 families, B = 400: 0.025, above the selection's α/2).
    Items at the same calibrated level are therefore ordered by the nominal log p of their
    leading family (the lexicographic order (calibrated p, nominal p), still a symmetric
    function of the items, so the test stays exact). A recording beyond every replicate of
    every family in nominal p has count 0 as under the nominal minimum, and then, beyond the
    bootstrap's resolution, the Bonferroni bound k·p of the leading family's nominal p.

    The leading family is the one with the smallest calibrated p on the recording, among
    those tied there the one with the smallest nominal p.

    Resolution: count 0 here holds exactly when no replicate of any family is at or beyond
    the recording's smallest nominal p (such a replicate makes its family's most extreme
    replicate, at rank 1, at or beyond it too), i.e. when the nominal minimum's count is 0,
    and the leading family is then the nominal minimum's. So at B = 400 and the selection's
    α/2 = 0.0025 (below 2/401, only count 0 is significant) the decision is the nominal
    minimum's; the calibration decides where count 1 or more can be significant (a larger
    α, or B + 1 ≥ k/(α/2): at the floor the most extreme replicate of each of the other
    k − 1 families can count).
    """
    lp = np.asarray(logp, float)
    L = np.column_stack([lp, np.asarray(logp_null, float)])  # (k, B + 1), item 0 the data
    L = np.where(np.isnan(L), 0.0, L)  # no statistic: p = 1
    k, n1 = L.shape
    S = np.sort(L, axis=1)
    # Integer ranks (ties counted against each item), compared exactly.
    rank = np.vstack([np.searchsorted(S[f], L[f], side="right") for f in range(k)])
    r_min = rank.min(axis=0)  # (B + 1,) each item's smallest calibrated p × (B + 1)
    at_min = np.where(rank == r_min, L, np.inf).min(axis=0)  # its leading family's log p
    lead = np.flatnonzero(rank[:, 0] == r_min[0])
    best = int(lead[np.argmin(L[lead, 0])])
    rep_r, rep_l = r_min[1:], at_min[1:]
    count = int(np.sum((rep_r < r_min[0]) | ((rep_r == r_min[0]) & (rep_l <= at_min[0]))))
    p_family = (1 + count) / n1
    if count == 0:  # beyond the bootstrap's resolution: Bonferroni over the families
        p_family = min(p_family, float(np.exp(L[best, 0])) * k)
    return p_family, best


def sidak_log(logp: np.ndarray | float, mult: int) -> np.ndarray:
    """log of the Šidák adjustment 1 − (1 − p)^mult, accurate for p down to exp(−1e300)."""
    lp = np.minimum(np.asarray(logp, float), 0.0)
    p = np.exp(lp)
    with np.errstate(divide="ignore"):
        exact = np.log(-np.expm1(mult * np.log1p(-np.minimum(p, 1 - 1e-16))))
    return np.where(p > 1e-12, exact, np.log(mult) + lp)


def chi2_logsf(stat: np.ndarray | float, k: int) -> np.ndarray:
    """log P(χ²_k > stat); the leading asymptotic term where scipy underflows."""
    x = np.maximum(np.asarray(stat, float), 0.0)
    with np.errstate(divide="ignore"):
        v = sps.chi2.logsf(x, k)
    a, z = k / 2.0, np.maximum(x / 2.0, 1e-300)
    # Evaluated everywhere, used only where scipy underflowed (large stat): at stat ≈ 0 it is
    # meaningless and its log of 0 must not print a warning onto the user's terminal.
    with np.errstate(divide="ignore", invalid="ignore"):
        asym = (a - 1) * np.log(z) - z - gammaln(a) + np.log1p((a - 1) / z)
    return np.where(np.isfinite(v), v, asym)


def f_logsf(f: np.ndarray | float, k: int, dof: int) -> np.ndarray:
    """log P(F_{k,dof} > f); the leading asymptotic term where scipy underflows."""
    f = np.maximum(np.asarray(f, float), 0.0)
    with np.errstate(divide="ignore"):
        v = sps.f.logsf(f, k, dof)
    a, b = dof / 2.0, k / 2.0
    x = dof / (dof + k * np.maximum(f, 1e-300))  # sf = I_x(a, b)
    with np.errstate(divide="ignore", invalid="ignore"):  # as in chi2_logsf: unused there
        asym = a * np.log(x) + b * np.log1p(-x) - np.log(a) - betaln(a, b)
    return np.where(np.isfinite(v), v, asym)


@dataclass(frozen=True)
class BoundedShared:
    """Errors shared by groups of whitened entries and *bounded*, not random: entry i moves
    by ``loading[i]·δ[group[i]]`` with every |δ_g| ≤ ``half`` (docs/diagnosis.md §2).

    Why (issue 22): a temperature channel quantised to q without dither records one code
    for the readings of a settled plateau, and its error is code − die, within ±q/2 — but
    not drawn at random per plateau: a die still settling towards a setpoint on a code has
    an error of the approach's sign on every plateau of a leg (a channel step of up to q
    between the legs), and one crossing a code's edge an error that follows its rate. A
    Gaussian draw of variance q²/12 per plateau left such nulls at 1.5 % at a 1 % level;
    the bound holds whatever the pattern.
    """

    group: np.ndarray  # (m,) int, 0..G − 1
    loading: np.ndarray  # (m,) the whitened effect of a unit error
    half: float  # the bound on each group's error, in the loading's units

    def reach(self, B: np.ndarray) -> float:
        """An upper bound of ‖Bᵀ Z δ‖ over the box (Z the groups' loading columns):
        :meth:`bound` of M = BᵀZ (:meth:`group_sums`)."""
        if B.shape[1] == 0 or np.asarray(self.group).size == 0:
            return 0.0
        return self.bound(self.group_sums(B))

    def group_sums(self, U: Any) -> np.ndarray:
        """(G, p) Σ over each group's entries of loading·U, i.e. (UᵀZ)ᵀ; by row blocks (U
        may be held as its recipe on a long recording)."""
        g = np.asarray(self.group)
        n_g = int(g.max()) + 1 if g.size else 0
        p = U.shape[1]
        out = np.zeros((n_g, p))
        for sl in row_blocks(g.size, p):
            Ui = np.asarray(U[sl]) * self.loading[sl, None]
            for j in range(p):
                out[:, j] += np.bincount(g[sl], Ui[:, j], minlength=n_g)
        return out

    def bound(self, M: np.ndarray) -> float:
        """An upper bound of ‖M δ‖ over the box, M (G, k) a set of columns' sums per group:
        the smaller of Σ_g ‖m_g‖·half (exact for one column: the worst δ_g is ±half by the
        sign of its sum; the triangle inequality for more) and ‖M‖₂·half·√G (the box's
        corners are half·√G from its centre; tighter where M spreads over several
        columns)."""
        if M.size == 0:
            return 0.0
        by_group = float(np.sum(np.linalg.norm(M, axis=1)))
        spectral = float(np.linalg.norm(M, 2)) * np.sqrt(M.shape[0])
        return self.half * min(by_group, spectral)

    def shortened(self, B: np.ndarray, e: np.ndarray) -> np.ndarray:
        """``e`` with its part along B's span shortened by :meth:`reach` (never past 0): any
        statistic of ``(Bᵀe, (I − BBᵀ)e)`` that grows with ‖Bᵀe‖ is then the one
        :func:`linear_stats` takes net of the box (an effect's own test, its columns B)."""
        sc = B.T @ e
        norm = float(np.linalg.norm(sc))
        if norm <= 0:
            return e
        return e - B @ sc * min(1.0, self.reach(B) / norm)

    def reading_reach(self, U: np.ndarray, idx: np.ndarray, Minv: np.ndarray) -> np.ndarray:
        """(N,) an upper bound of each reading's ‖((I − P)Zδ)_n‖ in the metric ``Minv``
        (its residual covariance's inverse, :func:`row_stats`) over the box:
        Σ_h ‖((I − P)z_h)_n‖·half — its own group's loading less the base model's share
        of every group's (a fit through the plateaus' errors moves the others too).
        ``idx`` (N, g): each reading's entries. Exact per group by blocks of readings; past
        :data:`REACH_BUDGET` elements the others' share is bounded through the reading's
        own ‖U_n‖ (Frobenius, in the metric) times Σ_h ‖Uᵀz_h‖."""
        grp = np.asarray(self.group)
        n_g = int(grp.max()) + 1 if grp.size else 0
        n, g = idx.shape
        C = self.group_sums(U).T  # (p, G)
        own_g = grp[idx[:, 0]]  # a reading's entries are in one group
        z_own = self.loading[idx]  # (N, g)
        out = np.empty(n)
        if n * g * n_g > REACH_BUDGET:
            UC = np.einsum("ngp,nhp->ngh", U[idx], U[idx])  # U_n U_nᵀ, (N, g, g)
            u_norm = np.sqrt(np.maximum(np.einsum("ngh,nhg->n", Minv, UC), 0.0))
            own = z_own - np.einsum("ngp,pn->ng", U[idx], C[:, own_g])
            own_norm = np.sqrt(np.maximum(np.einsum("ng,ngh,nh->n", own, Minv, own), 0.0))
            c_norm = np.linalg.norm(C, axis=0)
            return self.half * (own_norm + u_norm * (c_norm.sum() - c_norm[own_g]))
        for sl in row_blocks(n, g * max(n_g, 1)):
            R = -np.einsum("ngp,pk->ngk", U[idx[sl]], C)  # (c, g, G): −(U Uᵀ z_h)_n
            R[np.arange(R.shape[0]), :, own_g[sl]] += z_own[sl]
            out[sl] = np.sqrt(np.maximum(np.einsum("ngk,ngh,nhk->nk", R, Minv[sl], R),
                                         0.0)).sum(axis=1)
        return self.half * out


REACH_BUDGET = 50_000_000  # readings × entries × groups of the exact reading_reach


def _shrunk(norm: float, reach: float) -> float:
    """A score's norm less what a bounded shared error can reach (never below 0)."""
    return max(norm - reach, 0.0)


def linear_stats(
    U: np.ndarray,
    Xw: np.ndarray,
    e: np.ndarray,
    E: np.ndarray,
    one_sided: bool = False,
    EE: np.ndarray | None = None,
    bounded: BoundedShared | None = None,
) -> tuple[float, np.ndarray, int, float, float]:
    """F-type score test of free-gain columns after projecting out U.

    ``one_sided``: the first column's coefficient is physically > 0 (a lag's amplitude)
    and the others (N, e.g. the lag's unknown start) only exist with it. The evidence
    is ``‖P_N e‖² + z²`` when z > 0 and none otherwise (z the first column's score
    after N, whose sign is that of its fitted coefficient): the null law is
    ½·χ²_{j+1} on z > 0 (j = rank of N; z is independent of P_N e), p = 1 on z ≤ 0.
    Returns log p on the data, log p on each null replicate, the tested dof k, the
    absorbed fraction and the explained sum of squares. The noise scale is taken from
    the residual *after* the candidate, so the effect itself does not inflate it (short
    recordings, e.g. 33 rows; and strong effects, whose own signal would otherwise hide
    them): χ²_k tails become F(k, dof) tails. ``EE``: Σ E² per replicate, when the caller
    has it (it is the same for every candidate of a stage).

    ``bounded`` (:class:`BoundedShared`): the data may hold an error the null does not, known
    only to lie in a box. The data's score is taken as the least the box allows: its norm
    less the most the box can put into it (:meth:`BoundedShared.reach`), so that, whatever
    error in the box the data hold, its score is no larger than the noise alone would give
    (‖Bᵀ(ε + Zδ)‖ − reach ≤ ‖Bᵀε‖); the replicates are the noise's. One-sided: the signed
    score less its own reach, no evidence unless still > 0. The denominator (the residual
    after the candidate) and the explained sum of squares returned are the data's own.
    """
    if not one_sided and bounded is None and is_tall(*Xw.shape):
        return _linear_stats_by_rows(U, Xw, e, E, EE)
    absorbed = absorbed_fraction(U, Xw)
    m = e.size
    ee = float(e @ e)
    EE = sum_sq_columns(E) if EE is None else EE
    if one_sided:
        Nb = orthonormal_basis(project_out(U, Xw[:, 1:]), 1e-6)
        z1 = project_out(np.hstack([U, Nb]), Xw[:, :1])[:, 0]
        nz = float(np.linalg.norm(z1))
        if nz > 1e-6 * max(float(np.linalg.norm(Xw[:, 0])), 1e-300):
            b1 = z1 / nz
            j = Nb.shape[1]
            dof = max(m - U.shape[1] - j - 1, 1)

            def stat(qn: np.ndarray, t: np.ndarray, tot: np.ndarray) -> np.ndarray:
                c = (qn + t**2) / np.maximum((tot - qn - t**2) / dof, 1e-300)
                return np.where(t > 0, np.log(0.5) + f_logsf(c / (j + 1), j + 1, dof), 0.0)

            qn_d, t_d = float(np.sum((Nb.T @ e) ** 2)), float(b1 @ e)
            lp = float(stat(np.asarray(qn_d), np.asarray(t_d), np.asarray(ee)))
            if bounded is not None:  # the data's evidence at the least the box allows
                t_b = t_d - bounded.reach(b1[:, None])
                qn_b = _shrunk(np.sqrt(qn_d), bounded.reach(Nb)) ** 2
                c = (qn_b + t_b**2) / max((ee - qn_d - t_d**2) / dof, 1e-300)
                lp = (float(np.log(0.5) + f_logsf(c / (j + 1), j + 1, dof)) if t_b > 0
                      else 0.0)
            lpn = stat(np.sum(t_matmul(Nb, E) ** 2, axis=0), t_matmul(b1, E), EE)
            return lp, lpn, j + 1, absorbed, (qn_d + t_d**2) if t_d > 0 else 0.0
    B = orthonormal_basis(project_out(U, Xw), 1e-6)
    k = B.shape[1]
    if k == 0:
        return 0.0, np.zeros(E.shape[1]), 0, 1.0, 0.0
    dof = max(m - U.shape[1] - k, 1)
    q = float(np.sum((B.T @ e) ** 2))
    q_score = q if bounded is None else _shrunk(np.sqrt(q), bounded.reach(B)) ** 2
    f = q_score / k / max((ee - q) / dof, 1e-300)
    qn = np.sum(t_matmul(B, E) ** 2, axis=0)
    # the same floor as the data's F: a replicate whose residual lies wholly in B (EE = qn)
    # gave 0/0 = nan, which no comparison counts
    fn = qn / k / np.maximum((EE - qn) / dof, 1e-300)
    return float(f_logsf(f, k, dof)), f_logsf(fn, k, dof), k, absorbed, q


def _linear_stats_by_rows(U: np.ndarray, Xw: np.ndarray, e: np.ndarray, E: np.ndarray,
                          EE: np.ndarray | None) -> tuple[float, np.ndarray, int, float, float]:
    """:func:`linear_stats` (two-sided, no bound) for a tall ``Xw``, by row blocks.

    Why (issue 22, memory): the dense form holds the projected columns Z = (I − UUᵀ)Xw,
    their basis B and the temporaries of both, each (m × k): at 1 M readings ~150 MB apiece
    for a 6-column candidate, on top of the null replicates. Here only ``B``'s products
    are formed (:func:`scores_after`), with the tall route's steps of
    :func:`orthonormal_basis_tall`, so the statistics are the dense ones up to rounding.
    """
    m = e.size
    Be, BE, zz, tot, k = scores_after(U, Xw, e, E)
    absorbed = 1.0 if tot <= 0 else 1.0 - zz / tot
    if k == 0:
        return 0.0, np.zeros(E.shape[1]), 0, 1.0, 0.0
    ee = float(e @ e)
    EE = sum_sq_columns(E) if EE is None else EE
    dof = max(m - U.shape[1] - k, 1)
    q = float(np.sum(Be**2))
    f = q / k / max((ee - q) / dof, 1e-300)
    qn = np.sum(BE**2, axis=0)
    fn = qn / k / np.maximum((EE - qn) / dof, 1e-300)
    return float(f_logsf(f, k, dof)), f_logsf(fn, k, dof), k, absorbed, q


def is_tall(m: int, p: int) -> bool:
    """Whether an (m × p) float array takes the tall (Gram) route of
    :func:`orthonormal_basis`: larger than :data:`TALL_BYTES` and m > 20 p."""
    return 8 * m * p > TALL_BYTES and m > 20 * p


def scores_after(U: np.ndarray, Xw: np.ndarray, e: np.ndarray, E: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None, float, float, int]:
    """``Bᵀe``, ``BᵀE``, ‖Z‖², ‖Xw‖² and k, for B the orthonormal basis that
    ``orthonormal_basis_tall`` gives of Z = (I − UUᵀ)Xw, without an (m × k) array.

    The same steps by row blocks: C = UᵀXw; the Gram ZᵀZ of the rows
    ``Xw[i:j] − U[i:j]·C``; its eigen-cut T (:func:`eigen_cut_map`); H = (ZT)ᵀ(ZT) and
    (ZT)ᵀe, (ZT)ᵀE in one more pass; then B = ZT·R⁻¹ with RᵀR = H (Cholesky-QR2), so
    Bᵀe = R⁻ᵀ(ZT)ᵀe.
    """
    m, p = Xw.shape
    C = U.T @ Xw
    n_e = 0 if E is None else E.shape[1]
    width = p + U.shape[1] + n_e

    def z_rows(i: int, j: int) -> np.ndarray:
        return Xw[i:j] - np.asarray(U[i:j]) @ C

    gram = np.zeros((p, p))
    tot = 0.0
    for sl in row_blocks(m, width):
        Z = z_rows(sl.start, sl.stop)
        gram += Z.T @ Z
        tot += float(np.einsum("ij,ij->", Xw[sl], Xw[sl]))
    zz = float(np.trace(gram))
    T = eigen_cut_map(gram)
    k = T.shape[1]
    if k == 0:
        return np.zeros(0), None if E is None else np.zeros((0, n_e)), zz, tot, 0
    H = np.zeros((k, k))
    Ze = np.zeros(k)
    ZE = None if E is None else np.zeros((k, n_e))
    for sl in row_blocks(m, width):
        B1 = z_rows(sl.start, sl.stop) @ T
        H += B1.T @ B1
        Ze += B1.T @ e[sl]
        if E is not None:
            ZE += B1.T @ E[sl]
    Rt = np.linalg.cholesky(H)  # Rᵀ (lower): B = B1·R⁻¹, so Bᵀx = R⁻ᵀ·B1ᵀx
    Be = np.linalg.solve(Rt, Ze)
    BE = None if ZE is None else np.linalg.solve(Rt, ZE)
    return Be, BE, zz, tot, k


def explained_ss(
    U: np.ndarray, Xw: np.ndarray, e: np.ndarray, one_sided: bool = False
) -> tuple[float, int]:
    """‖Bᵀe‖² and k for the columns Xw after projecting out U (for profiling θ).

    ``one_sided`` as in :func:`linear_stats`: 0 when the first column's coefficient
    would be ≤ 0, so a refined θ never trades the physical sign for a better fit.
    A tall ``Xw`` two-sided: by row blocks (:func:`scores_after`).
    """
    if not one_sided and is_tall(*Xw.shape):
        Be, _, _, _, k = scores_after(U, Xw, e)
        return float(np.sum(Be**2)), k
    B = orthonormal_basis(project_out(U, Xw), 1e-6)
    q = float(np.sum((B.T @ e) ** 2))
    if one_sided and Xw.shape[1] > 0:
        Nb = orthonormal_basis(project_out(U, Xw[:, 1:]), 1e-6)
        z1 = project_out(np.hstack([U, Nb]), Xw[:, :1])[:, 0]
        if float(z1 @ e) <= 0:
            q = 0.0
    return q, B.shape[1]


def inverse_where(M: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(N, g, g): the inverse of each block ``M[i]`` where ``ok[i]``, zeros elsewhere, by
    blocks of readings (each block inverted on its own, as in one batch). Why (issue 22,
    memory): ``M[ok]`` and its inverse were two more (N, g, g) arrays at once."""
    Minv = np.zeros_like(M)
    for sl in row_blocks(M.shape[0], M[0].size if M.shape[0] else 1):
        keep = ok[sl]
        if keep.any():
            Minv[sl][keep] = np.linalg.inv(M[sl][keep])
    return Minv


def _child(rng: np.random.Generator) -> np.random.Generator:
    """An independent stream spawned from ``rng`` without advancing it (its own draws after
    are those it would have made); ``rng`` itself where it has no SeedSequence to spawn."""
    try:
        return rng.spawn(1)[0]
    except (TypeError, ValueError, AttributeError):
        return rng


def row_stats(
    U: np.ndarray,
    e: np.ndarray,
    E: np.ndarray,
    row: np.ndarray,
    n_rows: int,
    s: float,
    s_null: np.ndarray,
    skip: set[int],
    shared: np.ndarray | None = None,
    reading_dof: float = np.inf,
    rng: np.random.Generator | None = None,
    bounded: BoundedShared | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Leave-one-reading-out statistic per reading: e_gᵀ(C_g − U_g U_gᵀ)⁻¹ e_g / s².

    With white noise the residual's covariance on a reading is I − U_gU_gᵀ. With
    ``shared`` (the loading c of each entry on the reading's one temperature error, as in
    :func:`null_replicates`) the noise covariance is block-diagonal, C_g = diag(1 − c²) +
    c cᵀ, and the residual's is the g-block of (I − P)C(I − P) (:func:`_residual_cov_blocks`):
    the statistic is then the Mahalanobis distance, χ²_g under the null. Why: a
    recorded-temperature error moves the three axes together; the sum of squares of
    correlated entries has a far heavier tail than χ²_g, and such readings were named
    outliers (issue 10 nulls). C_g − U_gU_gᵀ is not that covariance: where the shared term
    dominates (c ≈ ±0.95 on all axes at the cold end) it is nearly singular and a null
    reading scored p ≈ 0.

    ``reading_dof`` ν finite (with ``rng``): the recording's readings are heavier-tailed
    than Gaussian (:func:`entry_tail_dof`, as diagnose reads it). Each null reading's
    statistic is multiplied by w / k, w ~ ν/χ²_ν drawn per reading and replicate and k =
    :func:`tail_scale` (ν): the Student-t scale mixture of that reading's noise (w), divided
    by the MAD scale² such noise gives (k), since the data's statistic is divided by its own
    MAD scale² (≈ k under the mixture) and the Gaussian replicates' by theirs (≈ 1); w·k
    would make the null k² too heavy (at ν = 5 the test at half its level).
    Only the per-reading family sees it; the replicates stay Gaussian for the others.

    ``bounded`` (:class:`BoundedShared`): each reading's data statistic is taken net of the
    most the box can put into it (:meth:`BoundedShared.reading_reach`), as the F tests'
    scores are (:func:`linear_stats`): a reading on a quantised channel's code, or a
    capture across a code change, whose rounding error alone sets it off is no outlier.

    Returns per-row stats on the data (N,), their max on each null replicate (B,),
    and the number of entries per reading (the dof).
    """
    mix = np.isfinite(reading_dof) and rng is not None
    k_mix = tail_scale(reading_dof) if mix else 1.0
    # The mixture's weights from a child stream (SeedSequence spawn: the parent's state does
    # not move), so whether the outlier family's null is a mixture does not change the draws
    # of the replicates after it (the other families' sign flips, the scan): at B = 400 and
    # α/2 = 1/401 one replicate decides, and a shifted stream moved a lag at 10⁻⁴·³⁵ from
    # count 0 to 1 by a sign-flip replicate of another family (issue 22).
    mix_rng = _child(rng) if mix else None
    g = int(np.bincount(row).max())
    idx = np.argsort(row, kind="stable").reshape(n_rows, g)
    if np.array_equal(idx.ravel(), np.arange(idx.size)):
        # Entries already grouped by reading (both modes): views, not (m × p), (m × B) copies.
        Ug = U.reshape(n_rows, g, -1)
        Eg = E.reshape(n_rows, g, -1)
    else:
        Ug, Eg = U[idx], E[idx]  # (N, g, p), (N, g, B)
    if shared is None:
        M = np.eye(g)[None] - np.einsum("ngp,nhp->ngh", Ug, Ug)
    else:
        M = _residual_cov_blocks(U, Ug, np.clip(shared, -1.0, 1.0), idx)
    ok = np.array([i not in skip for i in range(n_rows)]) & (np.linalg.det(M) > 1e-6)
    Minv = inverse_where(M, ok)
    eg = e[idx]
    t = np.einsum("ng,ngh,nh->n", eg, Minv, eg) / s**2
    if bounded is not None:  # net of what the box can put into the reading (linear_stats)
        reach = bounded.reading_reach(U, idx, Minv) / s
        t = np.where(ok, np.maximum(np.sqrt(np.maximum(t, 0.0)) - reach, 0.0) ** 2, t)
    # The max over readings by blocks of readings: no (N × B) array. s_null is one scale per
    # replicate, so max(q / s²) = max(q) / s².
    tn_max = np.full(E.shape[1], -np.inf)
    for sl in row_blocks(n_rows, g * max(E.shape[1], 1)):
        q = np.einsum("ngb,ngh,nhb->nb", Eg[sl], Minv[sl], Eg[sl])
        if mix:
            # w·q/k: the mixture's reading against the MAD scale k the mixture gives; the
            # replicates' own MAD scale (s_null) is the Gaussian's, 1.
            q *= reading_dof / mix_rng.chisquare(reading_dof, q.shape) / k_mix
        tn_max = np.maximum(tn_max, (q / s_null[None, :] ** 2).max(axis=0))
    return t, tn_max, g


# --- noise shared by the readings of one plateau ------------------------------------------
@dataclass
class SharedGroups:
    """Components of the noise that every entry of a group shares (docs/diagnosis.md §2,
    *Noise shared by a plateau*): component j adds ``loading[j][i] · b_j[group[j][i]]`` to
    whitened entry i, b_j ~ N(0, θ_j·s²) one draw per group.

    Why (issue 22): on a rig the readings of one plateau share errors — the die's
    temperature error of that plateau through ∂output/∂T, a quantised channel's offset, the
    chamber's state — and the base model, smooth in T, cannot absorb a random offset per
    plateau. Sign flips per reading destroy that shared part, so columns (nearly) constant
    within a plateau (a one-plateau change, hysteresis, a session step, a channel step) were
    tested against a null without it.
    """

    loading: list[np.ndarray]  # (m,) each
    group: list[np.ndarray]  # (m,) int each, 0..K_j − 1
    names: list[str]

    @property
    def sizes(self) -> list[int]:
        return [int(g.max()) + 1 if g.size else 0 for g in self.group]


SHARED_THETA_MAX = 1e3  # θ's upper bound (σ_b²/s²): far beyond any plateau's noise


def _group_columns(sg: SharedGroups, i: int, j: int) -> np.ndarray:
    """Rows i:j of Z = [Z_1, Z_2, …] (m × ΣK), Z_j[n, group_j[n]] = loading_j[n]."""
    sizes = sg.sizes
    Z = np.zeros((j - i, sum(sizes)))
    off = 0
    r = np.arange(j - i)
    for L, g, k in zip(sg.loading, sg.group, sizes, strict=True):
        Z[r, off + g[i:j]] = L[i:j]
        off += k
    return Z


def shared_variance(e: np.ndarray, U: np.ndarray, sg: SharedGroups
                    ) -> tuple[np.ndarray, float]:
    """Maximum-likelihood θ_j = σ_j²/s² of each shared component in e = (I − P)(ε + Σ Z_j b_j).

    ``c = Zᵀe`` is the only part of e the groups see: Cov(c) = s²(G + Σ_j θ_j G_{·j}G_{j·}),
    G = Zᵀ(I − P)Z (small: plateaus × axes + plateaus), s² the scatter outside
    span((I − P)Z), what no group explains (the within-plateau scatter). Directions the base
    model absorbs (G's eigenvalues below 1e-9 of the largest) are dropped. All in the groups'
    space: Z is formed by row blocks, never (m × ΣK) at once. Returns θ (one per component,
    0 where the likelihood does not rise above θ = 0) and s².
    """
    from scipy.optimize import minimize

    m = e.size
    nk = sum(sg.sizes)
    G = np.zeros((nk, nk))
    c = np.zeros(nk)
    UZ = np.zeros((U.shape[1], nk))
    for sl in row_blocks(m, max(nk, U.shape[1])):
        Z = _group_columns(sg, sl.start, sl.stop)
        G += Z.T @ Z
        c += Z.T @ e[sl]
        UZ += np.asarray(U[sl]).T @ Z
    G -= UZ.T @ UZ
    sizes = sg.sizes
    lam, V = np.linalg.eigh(G)
    keep = lam > 1e-9 * max(float(lam.max()), 1e-300)
    if not keep.any():
        return np.zeros(len(sg.sizes)), 1.0
    lam, V = lam[keep], V[:, keep]
    d = (V.T @ c) / np.sqrt(lam)  # Cov(d) = s²(I + Σ θ_j M_j)
    r = d.size
    s2 = float(max(e @ e - d @ d, 1e-300) / max(m - U.shape[1] - r, 1))
    T = V / np.sqrt(lam)  # (nk × r)
    Ms, off = [], 0
    for k in sizes:
        A = T.T @ G[:, off:off + k]  # (r × k)
        Ms.append(A @ A.T)
        off += k
    dd = d / np.sqrt(s2)

    def nll(th: np.ndarray) -> float:
        C = np.eye(r) + sum(t * M for t, M in zip(th, Ms, strict=True))
        sign, logdet = np.linalg.slogdet(C)
        return 0.5 * (logdet + float(dd @ np.linalg.solve(C, dd)))

    best, f_best = np.zeros(len(Ms)), nll(np.zeros(len(Ms)))
    for start in (0.01, 0.1, 1.0):
        res = minimize(nll, np.full(len(Ms), start), method="L-BFGS-B",
                       bounds=[(0.0, SHARED_THETA_MAX)] * len(Ms))
        if res.fun < f_best:
            best, f_best = res.x, float(res.fun)
    return best, s2


def within_groups(e: np.ndarray, sg: SharedGroups) -> np.ndarray:
    """``e`` minus each group's fitted offset (the first component: plateau × axis), each
    entry rescaled by 1/√(1 − L²/ΣL²) for the offset's own fit (the share of the entry's
    variance the group's mean took)."""
    L, g = sg.loading[0], sg.group[0]
    k = sg.sizes[0]
    ll = np.bincount(g, L * L, minlength=k)
    coef = np.bincount(g, L * e, minlength=k) / np.maximum(ll, 1e-300)
    h = L * L / np.maximum(ll[g], 1e-300)
    return (e - L * coef[g]) / np.sqrt(np.maximum(1.0 - h, 1.0 - LEVERAGE_MAX))


def add_shared(rng: np.random.Generator, sg: SharedGroups, theta: np.ndarray, s2: float,
               out: np.ndarray) -> np.ndarray:
    """``out[i] += Σ_j loading_j[i]·b_j[group_j[i]]``, b_j ~ N(0, θ_j·s²) per group and
    replicate (in place, by row blocks; not projected)."""
    draws = [rng.standard_normal((k, out.shape[1])) * np.sqrt(max(t, 0.0) * s2)
             for k, t in zip(sg.sizes, theta, strict=True)]
    for L, g, b, t in zip(sg.loading, sg.group, draws, theta, strict=True):
        if t <= 0:
            continue
        for sl in row_blocks(out.shape[0], out.shape[1]):
            out[sl] += L[sl, None] * b[g[sl]]
    return out
