"""One least-squares energy term ``E = sum r^2 + constant``: its value, gradient ``2 J^T r``
and Gauss-Newton Hessian ``2 J^T J`` (sparse), from residuals and a sparse Jacobian that the
terms assemble from dense blocks.

A term's Jacobian has the same sparsity pattern at every state of one topology and layout,
so its :class:`Pattern` can be kept and handed back: the next assembly then only scatters the
blocks' values into place (no indices built, nothing sorted, no block copied whole).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Pattern:
    """The CSR structure of a Jacobian assembled by :class:`Blocks`, valid for every later
    assembly that adds blocks of the same shapes at the same places (the same term on the
    same topology and layout).

    shape : (rows, columns)
    slots : tuple of int arrays
        One per block, in the order they were added: where each of the block's values goes in
        the CSR values, shaped like the block (``[..., m, b]``), or ``[..., k]`` where the
        block's ``nonzero`` was one ``[m, b]`` mask with ``k`` entries set. An entry that is
        not stored (left out by its mask, or its column by :meth:`keep_columns`) goes to
        ``nnz``, a slot past the matrix's values.
    masks : tuple of (bool [m, b] or None)
        The mask that compressed each block's slots (None: not compressed).
    indices, indptr : int
        The CSR column indices (sorted in each row) and row pointers.
    """

    shape: tuple[int, int]
    slots: tuple
    masks: tuple
    indices: np.ndarray
    indptr: np.ndarray

    @property
    def nnz(self) -> int:
        return len(self.indices)

    def keep_columns(self, columns: np.ndarray) -> Pattern:
        """The pattern of the Jacobian's columns ``columns`` (int [k], sorted) only: the
        Jacobians it assembles are ``[rows, k]``."""
        indices, indptr, kept = _renumbered(self.indices, self.indptr, self.shape[1], columns)
        count = len(indices)
        slot = np.full(self.nnz + 1, count, dtype=self.slots[0].dtype if self.slots else np.int64)
        slot[: self.nnz][kept] = np.arange(count)
        return Pattern(
            (self.shape[0], len(columns)), tuple(slot[s] for s in self.slots), self.masks,
            indices, indptr,
        )

    def matrix(self, blocks: list[np.ndarray]) -> sp.csr_matrix:
        """The Jacobian with the blocks' values ``blocks`` (each ``[..., m, b]``, broadcast
        against its slots, in add order)."""
        if len(blocks) != len(self.slots) or not all(
            _fits(v, s, m) for v, s, m in zip(blocks, self.slots, self.masks, strict=True)
        ):
            raise ValueError(
                "the blocks do not match the pattern's: a pattern fits only the term, topology "
                "and layout it was made for"
            )
        data = np.empty(self.nnz + 1)
        for values, slots, mask in zip(blocks, self.slots, self.masks, strict=True):
            values = values if mask is None else values[..., mask]
            # a compiled loop: numpy's broadcasting assignment took 2.5 times as long
            _scatter(data, slots.reshape(-1), np.broadcast_to(values, slots.shape).reshape(-1))
        return self.jacobian(data)

    def jacobian(self, data: np.ndarray) -> sp.csr_matrix:
        """The Jacobian whose CSR values are ``data`` [nnz + 1] (filled at the slots; the last
        entry takes the values of entries not stored)."""
        # indices and indptr are shared between assemblies and never written: the products
        # of the optimiser only read them
        jacobian = sp.csr_matrix((data[: self.nnz], self.indices, self.indptr), shape=self.shape)
        jacobian.has_sorted_indices = True
        return jacobian


class PatternCache:
    """The priors' Jacobian patterns kept between optimisations on one topology, layout and
    urshape (the hole filling's frames, one after the other), whatever their free unknowns.

    full : dict[tuple[str, bytes], Pattern]
        Each term's pattern of every column, by the term's name and the reach of the free
        columns it was made for (:func:`~.energy.total_energy`'s ``shared``).
    restricted : dict[str, Pattern]
        The same restricted to the last free columns (``total_energy``'s ``patterns``), and
        the structure of their Hessian (:class:`~.hessian.HessianPlan`).
    columns : bytes or None
        Those columns' key (:meth:`for_columns`); None before the first call.
    """

    def __init__(self):
        self.full: dict[tuple[str, bytes], Pattern] = {}
        self.restricted: dict = {}
        self.columns: bytes | None = None

    def for_columns(self, columns: np.ndarray | None) -> dict:
        """The restricted patterns for the free columns ``columns`` (int [k], sorted; None:
        all), emptied when they are not the last call's."""
        key = b"" if columns is None else np.asarray(columns, dtype=np.int64).tobytes()
        if key != self.columns:
            self.columns, self.restricted = key, {}
        return self.restricted


def keep_columns(matrix: sp.csr_matrix, columns: np.ndarray) -> sp.csr_matrix:
    """The columns ``columns`` (int [k], sorted) of ``matrix`` [R, n], as [R, k]: its entries
    renumbered (a product with a selection matrix counts and gathers them twice)."""
    indices, indptr, kept = _renumbered(matrix.indices, matrix.indptr, matrix.shape[1], columns)
    kept_matrix = sp.csr_matrix(
        (matrix.data[kept], indices, indptr), shape=(matrix.shape[0], len(columns))
    )
    kept_matrix.has_sorted_indices = matrix.has_sorted_indices
    return kept_matrix


def _renumbered(
    indices: np.ndarray, indptr: np.ndarray, width: int, columns: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The CSR column ``indices`` and row pointers ``indptr`` of a [R, width] matrix, keeping
    the columns ``columns`` (int [k], sorted) only, renumbered 0 .. k - 1; and which of the
    entries are kept (bool [nnz])."""
    columns = np.asarray(columns, dtype=np.int64)
    renumber = np.full(width, -1, dtype=np.int64)
    renumber[columns] = np.arange(len(columns))
    kept_indices = np.empty(len(indices), dtype=indices.dtype)
    kept_indptr = np.empty(len(indptr), dtype=indptr.dtype)
    kept = np.empty(len(indices), dtype=bool)
    count = _renumber(indices, indptr, renumber, kept_indices, kept_indptr, kept)
    return kept_indices[:count].copy(), kept_indptr, kept


@numba.njit(cache=True, nogil=True)
def _renumber(indices, indptr, renumber, kept_indices, kept_indptr, kept):
    """:func:`_renumbered` in one pass over the entries (numpy's gather, mask, cumulative
    sum and compaction took 7 of crane's 130 s, every hole filling frame's columns); returns
    the kept entries' count."""
    count = 0
    kept_indptr[0] = 0
    for row in range(len(indptr) - 1):
        for k in range(indptr[row], indptr[row + 1]):
            column = renumber[indices[k]]
            kept[k] = column >= 0
            if column >= 0:
                kept_indices[count] = column
                count += 1
        kept_indptr[row + 1] = count
    return count


def index_type(*sizes: int) -> type:
    """The integer type of sparse indices up to ``max(sizes)``: 32 bits where they fit (the
    indices are most of a Jacobian's memory)."""
    return np.int32 if max(sizes) < np.iinfo(np.int32).max else np.int64


@numba.njit(cache=True, nogil=True)
def _scatter(data: np.ndarray, slots: np.ndarray, values: np.ndarray) -> None:
    """``data[slots] = values`` (``slots`` and ``values`` flat, of one length)."""
    for k in range(slots.size):
        data[slots[k]] = values[k]


def _fits(values: np.ndarray, slots: np.ndarray, mask: np.ndarray | None) -> bool:
    """Whether a block's ``values`` [..., m, b] broadcast to its ``slots``."""
    block = values.shape[-2:]
    lead = slots.shape[:-1] if mask is not None else slots.shape[:-2]
    if block != (mask.shape if mask is not None else slots.shape[-2:]):
        return False
    try:
        return np.broadcast_shapes(values.shape[:-2], lead) == lead
    except ValueError:
        return False


@dataclass(frozen=True)
class Term:
    """An energy term at a state (derivatives w.r.t. the :class:`~.state.Layout` unknowns).

    value : float
    residuals : float64 [R]
        Weighted residuals ``r`` (square roots of the weights folded in).
    jacobian : csr_matrix [R, n] or None
        ``dr / dstep`` at ``step = 0`` (None when derivatives were not asked for).
    pattern : Pattern or None
        The Jacobian's structure, to hand to the next assembly of the same term.
    """

    value: float
    residuals: np.ndarray
    jacobian: sp.csr_matrix | None
    pattern: Pattern | None = None

    @property
    def gradient(self) -> np.ndarray:
        """``2 J^T r`` [n]."""
        return 2.0 * (self.jacobian.T @ self.residuals)

    @property
    def hessian(self) -> sp.csr_matrix:
        """The Gauss-Newton approximation ``2 J^T J`` [n, n]."""
        return (2.0 * (self.jacobian.T @ self.jacobian)).tocsr()


class Blocks:
    """Dense Jacobian blocks ``values [R, m, b]`` placed at (first row, first column) pairs,
    gathered into one sparse matrix; blocks must not overlap. Given the ``pattern`` of an earlier assembly of the same
    blocks, only their values are kept (and a pattern that keeps some columns only,
    :meth:`Pattern.keep_columns`, gives the Jacobian of those)."""

    def __init__(self, rows: int, columns: int, pattern: Pattern | None = None):
        self.shape = (rows, columns)
        if pattern is not None and pattern.shape[0] != rows:
            raise ValueError(f"the pattern has {pattern.shape[0]} rows, the blocks {rows}")
        self._pattern = pattern
        self._index = index_type(rows, columns)
        self._values: list[np.ndarray] = []
        self._rows: list[np.ndarray] = []
        self._cols: list[np.ndarray] = []
        # per block: its slots' shape, the stored entries among them (None: all) and its mask
        self._layouts: list[tuple] = []

    def add(
        self,
        row: np.ndarray,
        column: np.ndarray,
        values: np.ndarray,
        nonzero: np.ndarray | None = None,
    ) -> None:
        """Blocks ``values`` [..., m, b] starting at rows ``row`` [...] and columns ``column``
        [...] (broadcast against the blocks' leading shape). ``nonzero`` (bool, broadcast
        against ``values``) marks the entries that can be nonzero at any state, the others
        being left out of the matrix (an identity block's off-diagonal); default all."""
        values = np.asarray(values, dtype=np.float64)
        self._values.append(values)
        if self._pattern is not None:
            return
        m, b = values.shape[-2:]
        lead = np.broadcast_shapes(np.shape(row), np.shape(column), values.shape[:-2])
        index = self._index
        row = np.asarray(row, dtype=index)
        column = np.asarray(column, dtype=index)
        rows = np.broadcast_to(row, lead)[..., None, None] + np.arange(m, dtype=index)[:, None]
        cols = np.broadcast_to(column, lead)[..., None, None] + np.arange(b, dtype=index)[None, :]
        shape = (*lead, m, b)
        mask = kept = None
        if nonzero is not None and np.ndim(nonzero) <= 2:
            # one mask for every block: the slots keep its entries only
            mask = np.broadcast_to(np.asarray(nonzero, dtype=bool), (m, b)).copy()
            rows = np.broadcast_to(rows, shape)[..., mask].ravel()
            cols = np.broadcast_to(cols, shape)[..., mask].ravel()
            shape = (*lead, int(mask.sum()))
        else:
            rows = np.broadcast_to(rows, shape).ravel()
            cols = np.broadcast_to(cols, shape).ravel()
            if nonzero is not None:
                kept = np.broadcast_to(np.asarray(nonzero, dtype=bool), shape).ravel()
                rows, cols = rows[kept], cols[kept]
        self._rows.append(rows)
        self._cols.append(cols)
        self._layouts.append((shape, kept, mask))

    def pattern(self) -> Pattern:
        """The structure of the blocks added (the given pattern, if there was one)."""
        if self._pattern is not None:
            return self._pattern
        rows = np.concatenate([np.zeros(0, self._index)] + self._rows)
        cols = np.concatenate([np.zeros(0, self._index)] + self._cols)
        count = len(rows)
        slot = index_type(count)
        # each entry carries its number through the conversion (sorted in each row)
        numbers = np.arange(count, dtype=slot)
        structure = sp.coo_matrix((numbers, (rows, cols)), shape=self.shape).tocsr()
        if structure.nnz != count:
            raise ValueError("Jacobian blocks overlap: each entry must be added once")
        where = np.empty(count, dtype=slot)
        where[structure.data] = np.arange(count, dtype=slot)
        slots, masks, start = [], [], 0
        for shape, kept, mask in self._layouts:
            stored = int(np.prod(shape)) if kept is None else int(kept.sum())
            if kept is None:
                slots.append(where[start : start + stored].reshape(shape))
            else:
                full = np.full(len(kept), count, dtype=slot)
                full[kept] = where[start : start + stored]
                slots.append(full.reshape(shape))
            masks.append(mask)
            start += stored
        self._pattern = Pattern(
            self.shape, tuple(slots), tuple(masks), structure.indices, structure.indptr
        )
        self._rows.clear()
        self._cols.clear()
        self._layouts.clear()
        return self._pattern

    def matrix(self) -> sp.csr_matrix:
        values, self._values = self._values, []
        return self.pattern().matrix(values)


def term(
    residuals: np.ndarray,
    blocks: Blocks | sp.csr_matrix | None,
    constant: float = 0.0,
    *,
    pattern: Pattern | None = None,
) -> Term:
    """The :class:`Term` of ``residuals`` [R] (any shape, flattened in C order) with the
    Jacobian in ``blocks``, or the Jacobian itself (csr_matrix [R, n], with the ``pattern``
    it was filled from, if any; None: value only); ``constant`` adds to the value."""
    r = np.ascontiguousarray(residuals, dtype=np.float64).ravel()
    value = float(np.einsum("i,i->", r, r)) + float(constant)
    if blocks is None:
        return Term(value, r, None)
    if sp.issparse(blocks):
        return Term(value, r, blocks, pattern)
    return Term(value, r, blocks.matrix(), blocks.pattern())
