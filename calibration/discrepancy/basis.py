"""The orthonormal basis of a long recording's design, held as its recipe (issue 22, memory).

Every statistic projects out an orthonormal basis ``U`` (m × r) of the whitened design
(stats.py). On a long recording ``U`` was diagnose's largest array: at 1 M readings
(m = 3 M entries, r = 48) 1.15 GB, alive through every stage and the scan, next to the
null replicates, and with it ``diagnose`` took 3.1× ``calibrate``'s peak memory.

``U`` is the whitened design times a small matrix: ``U = X_w·S`` with ``S = T·R⁻¹``
(p × r; T from the scaled Gram matrix, R from one Cholesky-QR2 pass, as in
:func:`calibration.discrepancy.stats.orthonormal_basis_of_blocks`). :class:`RowBlockBasis`
keeps ``S`` and forms ``X_w`` one row block at a time whenever ``U`` is used, so its uses
cost the design's row blocks (16 MiB each) instead of an (m × r) array. It answers what
the statistics ask of ``U`` — ``shape``, ``U @ B``, ``U.T @ A``, row slices and row
indices (dense rows), ``U.reshape(N, g, -1)`` (a per-reading view whose ``np.einsum`` runs
by blocks of readings), ``np.hstack([U, B])`` (``B`` kept as extra columns) — with the
same values as the stored basis up to rounding; anything else gets the dense array.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.discrepancy import stats


def _by_rows(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    return a * (w if a.ndim == 1 else w.reshape((-1,) + (1,) * (a.ndim - 1)))


class WhitenedDesign:
    """The (m × p) whitened design ``[X0, X_1, …]·w`` given by its parts, used by row blocks.

    A part with ``rows_matmul``/``rows_rmatmul`` (problem.AxisBlockDesign) multiplies its
    rows without forming them (two thirds of the reference base design are zeros).
    """

    def __init__(self, parts: list[Any], w: np.ndarray) -> None:
        self.parts, self.w = parts, w
        self.cuts = np.cumsum([0] + [x.shape[1] for x in parts])
        self.m, self.p = w.size, int(self.cuts[-1])

    def rows(self, key: Any) -> np.ndarray:
        """Dense rows for a row slice or a 1-D array of row indices."""
        return np.hstack([x[key] for x in self.parts]) * self.w[key, None]

    def mul(self, i: int, j: int, C: np.ndarray) -> np.ndarray:
        """``rows(i:j) @ C``."""
        out = None
        for x, a, b in zip(self.parts, self.cuts[:-1], self.cuts[1:], strict=True):
            part = (x.rows_matmul(i, j, C[a:b]) if hasattr(x, "rows_matmul")
                    else x[i:j] @ C[a:b])
            out = part if out is None else out + part
        return _by_rows(self.w[i:j], out)

    def tmul(self, i: int, j: int, A: np.ndarray) -> np.ndarray:
        """``rows(i:j).T @ A`` (A: the j − i rows)."""
        Aw = _by_rows(self.w[i:j], A)
        return np.concatenate([x.rows_rmatmul(i, j, Aw) if hasattr(x, "rows_rmatmul")
                               else x[i:j].T @ Aw for x in self.parts])


class RowBlockBasis:
    """(m × r) orthonormal basis ``U = [X_w·S, extra]``, formed by row blocks on use."""

    ndim = 2
    dtype = np.dtype(float)

    def __init__(self, design: WhitenedDesign, S: np.ndarray,
                 extra: np.ndarray | None = None) -> None:
        self.design, self.S = design, S
        m, self._m, self._p = design.m, design.m, design.p
        self.extra = np.zeros((m, 0)) if extra is None else extra
        self.shape = (m, S.shape[1] + self.extra.shape[1])

    @classmethod
    def of_design(cls, design: WhitenedDesign) -> RowBlockBasis:
        """The basis of ``design``'s column space: Gram, eigen-cut, Cholesky-QR2.

        The same eigen-cut (``stats.eigen_cut_map``) as ``stats.orthonormal_basis_tall``;
        the Cholesky factor comes from ``Σ (B·T)ᵀ(B·T)`` over the row blocks B, so no
        (m × r) array is built.
        """
        rows, m, p = design.rows, design.m, design.p
        gram = np.zeros((p, p))
        for sl in stats.row_blocks(m, p):
            B = rows(sl)
            gram += B.T @ B
        T = stats.eigen_cut_map(gram)
        H = np.zeros((T.shape[1], T.shape[1]))
        for sl in stats.row_blocks(m, p):
            B1 = rows(sl) @ T
            H += B1.T @ B1
        R = np.linalg.cholesky(H).T  # upper: U₁ = U R
        return cls(design, T @ np.linalg.inv(R))

    def __len__(self) -> int:
        return self._m

    @property
    def T(self) -> _Transposed:  # noqa: N802 (numpy's name: the statistics write U.T)
        return _Transposed(self)

    def __getitem__(self, key: Any) -> np.ndarray:
        if isinstance(key, slice) and key.step in (None, 1):
            i, j, _ = key.indices(self._m)
            return self._dense(slice(i, max(i, j)))
        idx = np.asarray(key)
        if idx.dtype == bool and idx.ndim == 1:
            idx = np.flatnonzero(idx)
        if idx.ndim >= 1 and idx.dtype.kind in "iu":
            return self._dense(idx.ravel()).reshape(idx.shape + (self.shape[1],))
        return np.asarray(self)[key]

    def _dense(self, key: Any) -> np.ndarray:
        out = (self.design.mul(key.start, key.stop, self.S) if isinstance(key, slice)
               else self.design.rows(key) @ self.S)
        if self.extra.shape[1]:
            out = np.hstack([out, self.extra[key]])
        return out

    def __matmul__(self, B: np.ndarray) -> np.ndarray:
        B = np.asarray(B, float)
        r = self.S.shape[1]
        C = self.S @ B[:r]
        out = np.empty((self._m,) + B.shape[1:])
        for sl in stats.row_blocks(self._m, self._p):
            out[sl] = self.design.mul(sl.start, sl.stop, C)
        if self.extra.shape[1]:
            out += self.extra @ B[r:]
        return out

    def rmatmul_t(self, A: np.ndarray) -> np.ndarray:
        """``Uᵀ·A`` for A (m,) or (m × k): ``Sᵀ·Σ_blocks Bᵀ·A_block``, in double precision.

        A single-precision A (replicates beyond the null budget, stats.replicate_dtype) is
        cast one row block at a time, never whole (issue 22, memory)."""
        A = np.asarray(A)
        single = A.dtype == np.float32
        if not single:
            A = np.asarray(A, float)
        acc = np.zeros((self._p,) + A.shape[1:])
        more = np.zeros((self.extra.shape[1],) + A.shape[1:])
        for sl in stats.row_blocks(self._m, self._p):
            block = np.asarray(A[sl], float)
            acc += self.design.tmul(sl.start, sl.stop, block)
            if single and self.extra.shape[1]:
                more += self.extra[sl].T @ block
        out = self.S.T @ acc
        if self.extra.shape[1]:
            out = np.concatenate([out, more if single else self.extra.T @ A])
        return out

    def reshape(self, *shape: Any) -> np.ndarray | _ReadingBlocks:
        shape = tuple(shape[0]) if len(shape) == 1 and isinstance(shape[0], tuple) else shape
        if len(shape) == 3 and shape[0] * shape[1] == self._m and shape[2] in (-1, self.shape[1]):
            return _ReadingBlocks(self, int(shape[1]))
        return np.asarray(self).reshape(*shape)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        out = np.empty(self.shape)
        for sl in stats.row_blocks(self._m, self._p + self.shape[1]):
            out[sl] = self._dense(sl)
        return out if dtype is None else out.astype(dtype)

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        if func in (np.hstack, np.concatenate) and args and isinstance(args[0], list | tuple):
            parts = list(args[0])
            axis = kwargs.get("axis", 1 if func is np.hstack else 0)
            if (axis in (1, -1) and parts and parts[0] is self
                    and not any(isinstance(q, RowBlockBasis | _ReadingBlocks)
                                for q in parts[1:])):
                more = [np.asarray(q, float).reshape(self._m, -1) for q in parts[1:]]
                return RowBlockBasis(self.design, self.S, np.hstack([self.extra] + more))
        return func(*_dense_args(args), **_dense_args(kwargs))


class _Transposed:
    """``U.T`` of a :class:`RowBlockBasis`: what the statistics do with it is ``U.T @ A``."""

    def __init__(self, basis: RowBlockBasis) -> None:
        self.basis = basis
        self.shape = basis.shape[::-1]

    def __matmul__(self, A: np.ndarray) -> np.ndarray:
        return self.basis.rmatmul_t(A)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        return np.asarray(self.basis, dtype).T


class _ReadingBlocks:
    """``U.reshape(N, g, r)`` (entries grouped by reading): slices by readings are dense;
    ``np.einsum`` whose operands and output all lead with the reading index runs by blocks
    of readings (the statistics' per-reading forms, stats.row_stats)."""

    ndim = 3

    def __init__(self, basis: RowBlockBasis, g: int) -> None:
        self.basis, self.g = basis, g
        self.shape = (basis.shape[0] // g, g, basis.shape[1])

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key: Any) -> np.ndarray:
        if isinstance(key, slice) and key.step in (None, 1):
            i, j, _ = key.indices(self.shape[0])
            j = max(i, j)
            return self.basis[self.g * i:self.g * j].reshape(j - i, self.g, self.shape[2])
        return np.asarray(self)[key]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        return np.asarray(self.basis, dtype).reshape(self.shape)

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        if func is np.einsum and not kwargs and args and isinstance(args[0], str):
            out = _einsum_by_readings(args[0], args[1:], self)
            if out is not None:
                return out
        return func(*_dense_args(args), **_dense_args(kwargs))


def _einsum_by_readings(subscripts: str, operands: tuple, view: _ReadingBlocks
                        ) -> np.ndarray | None:
    """``np.einsum`` in blocks of readings when every operand and the output lead with the
    same (reading) index; None otherwise (the caller then builds the dense operands)."""
    if "->" not in subscripts or "." in subscripts:
        return None
    ins, out_spec = subscripts.replace(" ", "").split("->")
    specs = ins.split(",")
    if not out_spec or len(specs) != len(operands):
        return None
    lead = out_spec[0]
    n = view.shape[0]
    if any(s[:1] != lead or lead in s[1:] for s in specs) or lead in out_spec[1:]:
        return None
    if any(getattr(o, "shape", (None,))[:1] != (n,) for o in operands):
        return None
    out = None
    for sl in stats.row_blocks(n, view.g * max(view.shape[2], 1)):
        blocks: dict[int, np.ndarray] = {}  # an operand given twice is formed once
        part = np.einsum(subscripts, *[blocks.setdefault(id(o), o[sl]) for o in operands])
        if out is None:
            out = np.empty((n,) + part.shape[1:], part.dtype)
        out[sl] = part
    return out


def _dense_args(a: Any) -> Any:
    """Arguments with every implicit array replaced by its dense form (the fallback)."""
    if isinstance(a, RowBlockBasis | _ReadingBlocks | _Transposed):
        return np.asarray(a)
    if isinstance(a, list | tuple):
        return type(a)(_dense_args(x) for x in a)
    if isinstance(a, dict):
        return {k: _dense_args(v) for k, v in a.items()}
    return a
