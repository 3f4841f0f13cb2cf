"""One least-squares energy term ``E = sum r^2 + constant``: its value, gradient ``2 J^T r``
and Gauss-Newton Hessian ``2 J^T J`` (sparse), from residuals and a sparse Jacobian that the
terms assemble from dense blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Term:
    """An energy term at a state (derivatives w.r.t. the :class:`~.state.Layout` unknowns).

    value : float
    residuals : float64 [R]
        Weighted residuals ``r`` (square roots of the weights folded in).
    jacobian : csr_matrix [R, n] or None
        ``dr / dstep`` at ``step = 0`` (None when derivatives were not asked for).
    """

    value: float
    residuals: np.ndarray
    jacobian: sp.csr_matrix | None

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
    gathered into one sparse matrix."""

    def __init__(self, rows: int, columns: int):
        self.shape = (rows, columns)
        # 32-bit indices where they fit: the entries' indices are most of the memory
        self._index = np.int32 if max(rows, columns) < np.iinfo(np.int32).max else np.int64
        self._rows: list[np.ndarray] = []
        self._cols: list[np.ndarray] = []
        self._values: list[np.ndarray] = []

    def add(self, row: np.ndarray, column: np.ndarray, values: np.ndarray) -> None:
        """Blocks ``values`` [..., m, b] starting at rows ``row`` [...] and columns ``column``
        [...] (broadcast against the blocks' leading shape)."""
        values = np.asarray(values, dtype=np.float64)
        m, b = values.shape[-2:]
        lead = np.broadcast_shapes(np.shape(row), np.shape(column), values.shape[:-2])
        values = np.broadcast_to(values, (*lead, m, b))
        index = self._index
        row = np.asarray(row, dtype=index)
        column = np.asarray(column, dtype=index)
        row = np.broadcast_to(row, lead)[..., None, None] + np.arange(m, dtype=index)[:, None]
        column = (
            np.broadcast_to(column, lead)[..., None, None] + np.arange(b, dtype=index)[None, :]
        )
        self._rows.append(np.broadcast_to(row, values.shape).ravel())
        self._cols.append(np.broadcast_to(column, values.shape).ravel())
        self._values.append(values.ravel())

    def matrix(self) -> sp.csr_matrix:
        if not self._values:
            return sp.csr_matrix(self.shape)
        return sp.csr_matrix(
            (
                np.concatenate(self._values),
                (np.concatenate(self._rows), np.concatenate(self._cols)),
            ),
            shape=self.shape,
        )


def term(residuals: np.ndarray, blocks: Blocks | None, constant: float = 0.0) -> Term:
    """The :class:`Term` of ``residuals`` [R] (any shape, flattened in C order) with the
    Jacobian in ``blocks`` (None: value only); ``constant`` adds to the value."""
    r = np.ascontiguousarray(residuals, dtype=np.float64).ravel()
    return Term(
        float(np.einsum("i,i->", r, r)) + float(constant),
        r,
        None if blocks is None else blocks.matrix(),
    )
