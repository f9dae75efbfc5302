"""Tests a catalogue effect uses to check that a finding has its own physics' shape (issue 10).

A name is given only if the residual structure looks like the named physics. Two effects
carry such a check (docs/diagnosis.md §7, *Physics checks after selection*):

* ``outlier`` (:meth:`Outlier.misses`): a transient is *isolated*. Its deviation is not
  predicted by the other readings: the same position at other plateaus, the same
  orientation class (a smooth function of the reference direction), its neighbours in
  time on the same plateau.
* input-only terms (``scale_nonlinearity``, ``cross_coupling``: a function of the specific
  force alone, :meth:`CatalogueEffect.misses`): the same reference direction must leave the
  same residual at every visit; a term that leaves the visits of one direction different
  (a memory of the previous position) did not describe what it was fitted to.

Every test here is an F-type score test after projecting out an orthonormal basis ``U``
of the whitened model (:func:`calibration.discrepancy.stats.linear_stats`, noise from the
residual), on columns given in raw-output space (N,3,k) and lifted by the problem;
:func:`log_p_by_reading` is its form with the noise read reading by reading.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.discrepancy import stats
from calibration.discrepancy.context import AXES

# The same reference direction at two positions: within this many g on every axis (norm mode
# uses the calibrated output, whose noise is µg).
SAME_DIRECTION_G = 0.05


def whitened(pb: Any, x_raw: np.ndarray) -> np.ndarray:
    """(N,3,k) raw-output columns → whitened residual-space columns (m,k)."""
    return pb.whiten(pb.lift(x_raw))


def extend(U: np.ndarray, e: np.ndarray, Xw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Basis and residual after adding the whitened columns ``Xw`` to the model."""
    B = stats.orthonormal_basis(stats.project_out(U, Xw), 1e-6)
    return np.hstack([U, B]), e - B @ (B.T @ e)


def fitted_after(U: np.ndarray, e: np.ndarray, Xw: np.ndarray) -> np.ndarray:
    """The part of residual ``e`` that the whitened columns ``Xw`` fit after ``U`` (their
    least-squares fit with ``U`` projected out): where a structure found by :func:`log_p` is
    large."""
    Z = stats.project_out(U, Xw)
    return Z @ np.linalg.lstsq(Z, e, rcond=None)[0]


def log_p(U: np.ndarray, e: np.ndarray, Xw: np.ndarray) -> tuple[float, int]:
    """log p of the F score test of ``Xw`` after ``U`` (single test), and its dof (0: none)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        lp, _, k, _, _ = stats.linear_stats(U, Xw, e, np.zeros((e.size, 1)))
    return (float(lp), int(k)) if k > 0 else (0.0, 0)


def reading_shares(pb: Any, U: Any, e: np.ndarray, Z: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's share of the score of the columns ``Z`` (U already projected out) and
    the score itself: ``G[r] = Σ_{entries of reading r} Z ẽ`` on the HC2 residual
    ``ẽ = e/√(1 − h)`` (h the leverage of U), and ``s = Zᵀe`` (:func:`log_p_by_reading`)."""
    et = e / np.sqrt(1.0 - np.minimum(stats.leverage(U), stats.LEVERAGE_MAX))
    G = np.zeros((int(pb.row.max()) + 1, Z.shape[1]))
    np.add.at(G, pb.row, Z * et[:, None])
    return G, Z.T @ e


def log_p_by_reading(pb: Any, U: Any, e: np.ndarray, Xw: np.ndarray) -> tuple[float, int]:
    """log p of the columns ``Xw`` after ``U`` with the noise read reading by reading (a
    heteroscedasticity-robust score test), and its dof (0: none).

    The score is ``s = Zᵀe`` (Z = Xw with U projected out); its variance is taken as the
    sign-flip (wild) null's, one sign per reading, on the HC2 residual of the model without
    the columns (``ẽ = e/√(1 − h)``, h the leverage of U; stats.wild_replicates' residual):
    ``V = Σ_r g_r g_rᵀ``, ``g_r = Σ_{entries of reading r} Z ẽ``, in closed form rather than
    drawn. The residual is the null's (a score test's): the residual after the columns
    gave a variance too small under the null (the channel step's check on 200 nulls of
    gen2 seed 3 case 0139's protocol rejected 18 at 5 %, against 12 with this one). The
    cost is power where the columns catch only part of a structure: what they leave on
    their own readings counts as noise. ``T = sᵀV⁻¹s / k`` is judged against F(k, readings − k).

    Why (issue 22): :func:`log_p` takes one noise scale for the whole recording, from the
    residual. On the second generator a recording's plateaus are whitened unevenly (its
    quiet plateaus at 0.9–1.0 of unit variance, its vibrating ones at 0.7–0.8, the noise
    model's per-plateau scale shrunk towards the recording's), so a column that lives on
    the quiet plateaus ran above its level: the channel step's time check rejected 49 of 600
    nulls at 5 % (8 %) and 6 at 0.5 % (1 %) on five protocols of its benchmark cases, where
    this test rejects 36 (6 %) and 1. Each reading's own residual sets its own share here.
    """
    Z = stats.project_out(U, Xw)
    keep = np.linalg.norm(Z, axis=0) > 1e-9 * max(float(np.linalg.norm(Xw)), 1e-300)
    Z = Z[:, keep]
    k = Z.shape[1]
    n_read = int(np.unique(pb.row).size)
    if k == 0 or n_read <= k + 1:
        return 0.0, 0
    G, s = reading_shares(pb, U, e, Z)
    V = G.T @ G
    try:
        t = float(s @ np.linalg.solve(V, s))
    except np.linalg.LinAlgError:
        return 0.0, 0
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(stats.f_logsf(t / k, k, n_read - k)), k


def log_p_by_plateau(pb: Any, U: np.ndarray, e: np.ndarray, Xw: np.ndarray
                     ) -> tuple[float, int]:
    """:func:`log_p` with each plateau's entries scaled by that plateau's own noise scale,
    and its dof (0: none).

    The scale of plateau j is ``s_j² = Σ e² / Σ (1 − h)`` over its entries (``e`` the
    residual of the model ``U`` without the columns, h the leverage of U); rows of the
    model, residual and columns are divided by it, the model re-orthonormalised, and the
    pooled F test taken on that. With one plateau it is :func:`log_p`.

    Why (issue 22): on the second generator a recording's quiet plateaus whiten to
    0.9–1.0 of unit variance and its vibrating ones to 0.7–0.8, and :func:`log_p`'s one scale
    ran the checks whose columns live on some plateaus above their level: on 600 nulls of
    seed 2, at 5 %, the input-only check's per-visit offsets rejected 7.2 % and the free
    offset per direction 8.3 % (9.5 % after the products of two axes' inputs); scaled by
    plateau, 4.8 %, 5.5 % and 4.5 %. :func:`log_p_by_reading` is no substitute there: with
    many columns, each carried by a few readings, its sign-flip variance reads a
    self-normalised sum, whose tail is far lighter than F(k, ·)'s (0 of 600 at 5 %).
    """
    step = pb.ctx.steps[pb.row]
    h = stats.leverage(U)
    d = np.ones(e.size)
    for j in np.unique(step):
        on = step == j
        v = float(e[on] @ e[on]) / max(float(np.sum(1.0 - h[on])), 1e-12)
        d[on] = 1.0 / np.sqrt(max(v, 1e-300))
    if np.ptp(d) == 0.0:
        return log_p(U, e, Xw)
    Ud = stats.orthonormal_basis(U * d[:, None])
    ed = d * e
    return log_p(Ud, ed - Ud @ (Ud.T @ ed), Xw * d[:, None])


def per_axis_indicator(n: int, rows: np.ndarray, axes: tuple[int, ...] = (0, 1, 2)) -> np.ndarray:
    """(N,3,len(axes)): 1 on ``rows`` of each listed axis (an offset there)."""
    out = np.zeros((n, 3, len(axes)))
    for j, a in enumerate(axes):
        out[rows, a, j] = 1.0
    return out


def position_directions(positions: np.ndarray, input_g: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference direction of each position: (position ids, sorted; the direction index
    of each id; each reading's index into the ids).

    A position's direction is the median of its readings' inputs; positions are taken in
    id order, each joining the first direction whose first position is within
    :data:`SAME_DIRECTION_G` on every axis. The readings are grouped by one sort, not one
    pass over all readings per position: a tiled schedule of 1 M readings has ~90 k
    position ids, and the per-id masks took 10 min of a diagnosis (issue 22).
    """
    ids, inverse = np.unique(positions, return_inverse=True)
    order = np.argsort(inverse, kind="stable")  # each id's readings in recording order
    rows_of = np.split(order, np.flatnonzero(np.diff(inverse[order])) + 1)
    centre: list[np.ndarray] = []
    direction = np.empty(ids.size, dtype=int)
    for k, rows in enumerate(rows_of):
        d = np.median(input_g[rows], axis=0)
        for j, c in enumerate(centre):
            if np.all(np.abs(c - d) < SAME_DIRECTION_G):
                direction[k] = j
                break
        else:
            direction[k] = len(centre)
            centre.append(d)
    return ids, direction, inverse.reshape(-1)


def direction_ids(positions: np.ndarray, input_g: np.ndarray) -> np.ndarray:
    """(N,) index of each reading's reference direction (:func:`position_directions`)."""
    _ids, direction, inverse = position_directions(positions, input_g)
    return direction[inverse]


def direction_groups(positions: np.ndarray, input_g: np.ndarray) -> list[list[int]]:
    """Positions that put the same reference direction on the sensor (≥ 2 positions each),
    in order of their first position (:func:`position_directions`)."""
    ids, direction, _inverse = position_directions(positions, input_g)
    groups = [[int(p) for p in ids[direction == j]] for j in range(int(direction.max()) + 1)] \
        if ids.size else []
    return [g for g in groups if len(g) >= 2]


def visits_differ(
    pb: Any, U: np.ndarray, e: np.ndarray, positions: list[int], axes: list[str], alpha: float
) -> dict[str, Any] | None:
    """Residuals that differ between visits of the same reference direction (issue 10).

    ``U``, ``e``: the model *with* the input-only term. With a reference, every direction
    the schedule revisits on all three axes; in norm mode only the term's own places (the
    direction groups holding its ``where`` positions) and axes. Per group and axis, an
    offset per position is tested after an offset per direction (the contrast between
    visits). A function of the specific force predicts no contrast, so under it
    the test rejects with probability α; an orientation history (the previous position)
    makes it. Returns the place (positions, axes, log10 p) when significant at α. The
    F test scales each plateau by its own noise (:func:`log_p_by_plateau`).
    """
    ctx = pb.ctx
    groups = direction_groups(ctx.positions, ctx.input_g)
    if pb.mode == "reference":
        # Every revisited direction, every axis (issue 22): an offset that follows the table's
        # pose rather than the force (a cable wound round the inner axis: several table
        # angles give +z) leaves its contrast where the term's own columns are zero (at ±z for
        # products of inputs), so a check confined to the term's places never saw it. Only
        # with a reference: there a revisit is the commanded direction again; in norm mode
        # the directions are read from the output, and a group is hand placements up to
        # SAME_DIRECTION_G apart, whose contrast a function of the force makes too.
        ax: tuple[int, ...] = (0, 1, 2)
    else:
        groups = [g for g in groups if set(g) & set(positions)]
        ax = tuple(AXES.index(a) for a in axes if a in AXES) or (0, 1, 2)
    if not groups:
        return None
    n_visits = sum(len(g) for g in groups)
    if pb.mode == "reference" and 8 * pb.m * 3 * n_visits > stats.TALL_BYTES:
        lp, k = _visits_log_p_by_labels(pb, U, e, groups)
    else:
        common, visit = [], []
        for g in groups:
            common.append(per_axis_indicator(ctx.n, np.isin(ctx.positions, g), ax))
            visit += [per_axis_indicator(ctx.n, ctx.positions == p, ax) for p in g]
        Uc, ec = extend(U, e, whitened(pb, np.concatenate(common, axis=2)))
        # Each plateau at its own noise scale (issue 22, :func:`log_p_by_plateau`); a long
        # recording's form by labels above keeps one scale for the recording.
        lp, k = log_p_by_plateau(pb, Uc, ec, whitened(pb, np.concatenate(visit, axis=2)))
    if k == 0 or lp > np.log(alpha):
        return None
    return {
        "positions": sorted(p for g in groups for p in g),
        "axes": [AXES[a] for a in ax],
        "log10_p": round(float(lp / np.log(10)), 1),
    }


def _visits_log_p_by_labels(pb: Any, U: Any, e: np.ndarray, groups: list[list[int]]
                            ) -> tuple[float, int]:
    """:func:`log_p` of the per-visit offsets after ``U`` and the per-direction offsets, as
    :func:`visits_differ` computes it densely, in the offsets' own space (reference mode).

    Why (issue 22, memory): on a long recording of a repeated schedule every visit is a
    position of its own, and the dense columns (one per position and axis, m entries each)
    would be 3 × positions × m floats (27,000 positions at 300 k readings: 196 TB). Both
    sets of columns are indicators of disjoint entries, and the per-direction ones lie in
    the span of the per-visit ones, so the test needs only ``‖P_[U,X] e‖²`` and the rank
    each adds (:func:`_explained_by_labels`): F = (q_visit − q_dir)/k over the residual
    after both, with the dense form's dof.
    """
    ctx = pb.ctx
    axis = pb.axis
    visit_of = {p: i for i, p in enumerate(p for g in groups for p in g)}
    group_of = {p: i for i, g in enumerate(groups) for p in g}
    visit = np.array([visit_of.get(int(p), -1) for p in ctx.positions])[pb.row]
    group = np.array([group_of.get(int(p), -1) for p in ctx.positions])[pb.row]
    q_dir, k_dir = _explained_by_labels(pb, U, e, np.where(group >= 0, 3 * group + axis, -1),
                                        3 * len(groups))
    q_vis, k_vis = _explained_by_labels(pb, U, e, np.where(visit >= 0, 3 * visit + axis, -1),
                                        3 * len(visit_of))
    k = k_vis - k_dir
    if k <= 0:
        return 0.0, 0
    q = q_vis - q_dir
    dof = max(e.size - (U.shape[1] + k_dir) - k, 1)
    ee = float(e @ e) - q_dir
    f = q / k / max((ee - q) / dof, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(stats.f_logsf(f, k, dof)), k


LABEL_RANK_TOL = 1e-10  # eigenvalue cut of I − AᵀA (singular values of (I − P_X)U, ≤ 1)


def _explained_by_labels(pb: Any, U: Any, e: np.ndarray, labels: np.ndarray, n_labels: int
                         ) -> tuple[float, int]:
    """``‖P_[U,X] e‖²`` and ``rank([U, X]) − rank(U)`` for X the whitened indicators of
    ``labels`` (entry i in column ``labels[i]``, none where −1), ``U`` orthonormal and ``e``
    orthogonal to it.

    X's columns have disjoint supports, so Q = X·D^-½ is orthonormal and
    ``P_[U,X] = P_Q + P_W`` with W = (I − P_Q)U: ``‖P_Q e‖² = ‖c‖²``, c = Qᵀe, and, as
    Uᵀe = 0, ``Wᵀe = −Aᵀc``, ``WᵀW = I − AᵀA`` with A = QᵀU (n_labels × r, summed over
    row blocks of U). No (m × n_labels) array.
    """
    c, _, A, lam, V, keep, n_used = _label_parts(pb, U, e, labels, n_labels)
    b = V[:, keep].T @ (A.T @ c)
    return float(c @ c + np.sum(b**2 / lam[keep])), n_used + int(keep.sum()) - U.shape[1]


def _label_parts(pb: Any, U: Any, e: np.ndarray, labels: np.ndarray, n_labels: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                            np.ndarray, int]:
    """The pieces of :func:`_explained_by_labels`: c = Qᵀe, Q's column scale ``inv``,
    A = QᵀU, the eigenpairs (λ, V) of I − AᵀA, the kept ones, and the labels used."""
    from scipy import sparse

    on = labels >= 0
    w = pb.w
    norm = np.sqrt(np.bincount(labels[on], w[on] ** 2, minlength=n_labels))
    used = norm > 0
    inv = np.where(used, 1.0 / np.where(used, norm, 1.0), 0.0)
    c = np.bincount(labels[on], (w * e)[on], minlength=n_labels) * inv
    r = U.shape[1]
    A = np.zeros((n_labels, r))
    for blk in stats.row_blocks(e.size, r):
        i, j = blk.start, blk.stop
        sel = np.flatnonzero(on[i:j])
        S = sparse.csr_matrix((w[i:j][sel], (labels[i:j][sel], sel)), shape=(n_labels, j - i))
        A += S @ np.asarray(U[i:j])
    A *= inv[:, None]
    lam, V = np.linalg.eigh(np.eye(r) - A.T @ A)
    keep = lam > LABEL_RANK_TOL
    return c, inv, A, lam, V, keep, int(used.sum())


def fitted_by_labels(pb: Any, U: Any, e: np.ndarray, labels: np.ndarray, n_labels: int
                     ) -> np.ndarray:
    """:func:`fitted_after` for X the whitened indicators of ``labels`` (as
    :func:`_explained_by_labels`), ``e`` orthogonal to ``U``: ``P_[U,X] e`` without an
    (m × n_labels) array.

    With W = (I − P_Q)U, ``P_W e = W·g``, g = −V Λ⁺ Vᵀ Aᵀc, and ``W·g = U·g − Q·(A·g)``,
    so the fit is ``Q·(c − A·g) + U·g`` (Q's entry on row i: w_i / ‖X's column l_i‖).
    """
    c, inv, A, lam, V, keep, _ = _label_parts(pb, U, e, labels, n_labels)
    g = -V[:, keep] @ ((V[:, keep].T @ (A.T @ c)) / lam[keep])
    coef = c - A @ g
    on = labels >= 0
    fit = np.zeros(e.size)
    fit[on] = pb.w[on] * inv[labels[on]] * coef[labels[on]]
    for sl in stats.row_blocks(e.size, U.shape[1]):
        fit[sl] += np.asarray(U[sl]) @ g
    return fit


def log_p_by_labels(pb: Any, U: Any, e: np.ndarray, labels: np.ndarray, n_labels: int
                    ) -> tuple[float, int]:
    """:func:`log_p` of the whitened indicators of ``labels`` after ``U`` (``e`` orthogonal
    to it), in the indicators' own space: F = (q/k) / ((‖e‖² − q)/dof), q = ‖P_[U,X]e‖²,
    k the rank X adds, dof = m − rank(U) − k (``stats.linear_stats``'s)."""
    q, k = _explained_by_labels(pb, U, e, labels, n_labels)
    if k <= 0:
        return 0.0, 0
    dof = max(e.size - U.shape[1] - k, 1)
    f = q / k / max((float(e @ e) - q) / dof, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(stats.f_logsf(f, k, dof)), k


class StackedRows:
    """(m × (r + s)) ``[U, Z·M]`` given by row slices: ``U`` (array or row-block basis) and
    the extra columns' whitened rows ``rows(i, j)`` ((j − i) × p) times M (p × s)."""

    ndim = 2

    def __init__(self, U: Any, rows: Any, M: np.ndarray) -> None:
        self.U, self.rows, self.M = U, rows, M
        self.shape = (U.shape[0], U.shape[1] + M.shape[1])

    def extra(self, i: int, j: int) -> np.ndarray:
        """Rows i:j of the added columns (Z·M, Z = X − U·C projected: see extend_by_rows)."""
        return self.rows(i, j) @ self.M

    def __getitem__(self, key: slice) -> np.ndarray:
        i, j, _ = key.indices(self.shape[0])
        return np.hstack([np.asarray(self.U[i:j]), self.extra(i, j)])


def extend_by_rows(U: Any, e: np.ndarray, rows: Any, p: int
                   ) -> tuple[StackedRows, np.ndarray]:
    """:func:`extend` for whitened columns given by row blocks ``rows(i, j)`` (m × p), the
    tall route of ``stats.orthonormal_basis`` (Gram, eigen-cut, Cholesky-QR2) on
    Z = (I − P_U)X, with no (m × p) array: Z's rows are ``rows(i, j) − U[i:j]·C``,
    C = UᵀX, and the basis is Z·M (issue 22, memory: at 1 M readings the turn of the
    reference's 60 columns are 1.4 GB each as raw, lifted, projected and basis arrays).
    """
    m, r = e.size, U.shape[1]
    width = p + r
    C = np.zeros((r, p))
    for sl in stats.row_blocks(m, width):
        C += np.asarray(U[sl]).T @ rows(sl.start, sl.stop)

    def z_rows(i: int, j: int) -> np.ndarray:
        return rows(i, j) - np.asarray(U[i:j]) @ C

    gram = np.zeros((p, p))
    for sl in stats.row_blocks(m, width):
        Z = z_rows(sl.start, sl.stop)
        gram += Z.T @ Z
    T = stats.eigen_cut_map(gram)
    H = np.zeros((T.shape[1], T.shape[1]))
    for sl in stats.row_blocks(m, width):
        B1 = z_rows(sl.start, sl.stop) @ T
        H += B1.T @ B1
    M = T @ np.linalg.inv(np.linalg.cholesky(H).T)
    Ut = StackedRows(U, z_rows, M)
    be = np.zeros(M.shape[1])
    for sl in stats.row_blocks(m, width):
        be += Ut.extra(sl.start, sl.stop).T @ e[sl]
    et = e.copy()
    for sl in stats.row_blocks(m, width):
        et[sl] -= Ut.extra(sl.start, sl.stop) @ be
    return Ut, et
