"""One least-squares energy term ``E = sum r^2 + constant``: its value, gradient ``2 J^T r``
and Gauss-Newton Hessian ``2 J^T J`` (sparse), from residuals and a sparse Jacobian that the
terms assemble from dense blocks.

A term's Jacobian has the same sparsity pattern at every state of one topology and layout,
so its :class:`Pattern` can be kept and handed back: the next assembly then only gathers the
blocks' values into place (no indices built, nothing sorted).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Pattern:
    """The CSR structure of a Jacobian assembled by :class:`Blocks`, valid for every later
    assembly that adds blocks of the same shapes at the same places (the same term on the
    same topology and layout).

    shape : (rows, columns)
    order : int [nnz]
        Entry ``k`` of the CSR values is entry ``order[k]`` of the blocks' values, flattened
        and concatenated in the order they were added.
    indices, indptr : int
        The CSR column indices (sorted in each row) and row pointers.
    entries : int
        How many values the blocks hold (more than ``nnz`` where structural zeros or columns
        were left out).
    """

    shape: tuple[int, int]
    order: np.ndarray
    indices: np.ndarray
    indptr: np.ndarray
    entries: int

    def keep_columns(self, columns: np.ndarray) -> Pattern:
        """The pattern of the Jacobian's columns ``columns`` (int [k], sorted) only: the
        Jacobians it assembles are ``[rows, k]``."""
        columns = np.asarray(columns, dtype=np.int64)
        renumber = np.full(self.shape[1], -1, dtype=np.int64)
        renumber[columns] = np.arange(len(columns))
        renumbered = renumber[self.indices]
        kept = renumbered >= 0
        before = np.concatenate([[0], np.cumsum(kept)])
        return Pattern(
            (self.shape[0], len(columns)),
            self.order[kept],
            renumbered[kept].astype(self.indices.dtype),
            before[self.indptr].astype(self.indptr.dtype),
            self.entries,
        )

    def matrix(self, values: np.ndarray) -> sp.csr_matrix:
        """The Jacobian with the blocks' values ``values`` [nnz] (flattened, in add order)."""
        if len(values) != self.entries:
            raise ValueError(
                f"the blocks hold {len(values)} values, the pattern {self.entries}: "
                "a pattern fits only the term, topology and layout it was made for"
            )
        # indices and indptr are shared between assemblies and never written: the products
        # of the optimiser only read them
        jacobian = sp.csr_matrix((values[self.order], self.indices, self.indptr), shape=self.shape)
        jacobian.has_sorted_indices = True
        return jacobian


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
        # 32-bit indices where they fit: the entries' indices are most of the memory
        self._index = np.int32 if max(rows, columns) < np.iinfo(np.int32).max else np.int64
        self._rows: list[np.ndarray] = []
        self._cols: list[np.ndarray] = []
        self._numbers: list[np.ndarray] = []
        self._values: list[np.ndarray] = []
        self._entries = 0

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
        m, b = values.shape[-2:]
        lead = np.broadcast_shapes(np.shape(row), np.shape(column), values.shape[:-2])
        values = np.broadcast_to(values, (*lead, m, b))
        first = self._entries
        self._entries += values.size
        self._values.append(values.ravel())
        if self._pattern is not None:
            return
        index = self._index
        row = np.asarray(row, dtype=index)
        column = np.asarray(column, dtype=index)
        row = np.broadcast_to(row, lead)[..., None, None] + np.arange(m, dtype=index)[:, None]
        column = (
            np.broadcast_to(column, lead)[..., None, None] + np.arange(b, dtype=index)[None, :]
        )
        rows = np.broadcast_to(row, values.shape).ravel()
        columns = np.broadcast_to(column, values.shape).ravel()
        numbers = np.arange(first, self._entries, dtype=np.int64)
        if nonzero is not None:
            kept = np.broadcast_to(np.asarray(nonzero, dtype=bool), values.shape).ravel()
            rows, columns, numbers = rows[kept], columns[kept], numbers[kept]
        self._rows.append(rows)
        self._cols.append(columns)
        self._numbers.append(numbers)

    def pattern(self) -> Pattern:
        """The structure of the blocks added (the given pattern, if there was one)."""
        if self._pattern is not None:
            return self._pattern
        rows = np.concatenate([np.zeros(0, self._index)] + self._rows)
        cols = np.concatenate([np.zeros(0, self._index)] + self._cols)
        count = len(rows)
        number = np.int32 if self._entries < np.iinfo(np.int32).max else np.int64
        numbers = np.concatenate([np.zeros(0, number)] + self._numbers).astype(number)
        # each entry carries its number through the conversion (sorted in each row)
        structure = sp.coo_matrix((numbers, (rows, cols)), shape=self.shape).tocsr()
        if structure.nnz != count:
            raise ValueError("Jacobian blocks overlap: each entry must be added once")
        self._pattern = Pattern(
            self.shape, structure.data, structure.indices, structure.indptr, self._entries
        )
        self._rows.clear()
        self._cols.clear()
        self._numbers.clear()
        return self._pattern

    def matrix(self) -> sp.csr_matrix:
        values = np.concatenate([np.zeros(0)] + self._values)
        self._values.clear()
        return self.pattern().matrix(values)


def term(residuals: np.ndarray, blocks: Blocks | None, constant: float = 0.0) -> Term:
    """The :class:`Term` of ``residuals`` [R] (any shape, flattened in C order) with the
    Jacobian in ``blocks`` (None: value only); ``constant`` adds to the value."""
    r = np.ascontiguousarray(residuals, dtype=np.float64).ravel()
    value = float(np.einsum("i,i->", r, r)) + float(constant)
    if blocks is None:
        return Term(value, r, None)
    return Term(value, r, blocks.matrix(), blocks.pattern())
