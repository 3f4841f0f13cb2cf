"""Back-substitution with the triangular factors of a sparse matrix factorised once and solved
many times with a few right sides at once.

SuperLU (``scipy.sparse.linalg.splu``) solves each right-hand column on its own; the ARAP-ICP
of :mod:`fourd.methods.kinematic.register` solves ``(L + w I) X = B`` with the three columns of
the vertex positions some 30 times per registered frame with one factorisation. Reading the
factors once for all three columns takes well under half the time (crane's template of 10,026
vertices, 383,000 factor entries, with the elimination-order gather and scatter: 2.0 ms per
solve through SuperLU, 0.84 ms here; medians of 200).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import pymetis
import scipy.sparse as sp


@dataclass(frozen=True)
class TriangularFactors:
    """``A = L U`` of an ``[n, n]`` matrix factorised without row or column permutation, as
    CSR arrays: ``L``'s strictly lower part (its diagonal is 1), ``U``'s strictly upper part
    and the inverse of ``U``'s diagonal [n]."""

    lower_indptr: np.ndarray
    lower_indices: np.ndarray
    lower_data: np.ndarray
    upper_indptr: np.ndarray
    upper_indices: np.ndarray
    upper_data: np.ndarray
    inverse_diagonal: np.ndarray


def unpermuted_factors(lu) -> TriangularFactors | None:
    """The factors of a ``scipy.sparse.linalg.SuperLU`` object, or None when it permuted rows
    or columns (then only its own ``solve`` applies) or a pivot is zero."""
    n = lu.shape[0]
    identity = np.arange(n)
    if not (np.array_equal(lu.perm_r, identity) and np.array_equal(lu.perm_c, identity)):
        return None
    upper = lu.U.tocsr()
    diagonal = upper.diagonal()
    if not np.all(np.isfinite(diagonal)) or np.any(diagonal == 0.0):
        return None
    strict_lower = sp.tril(lu.L, k=-1, format="csr")
    strict_upper = sp.triu(upper, k=1, format="csr")
    return TriangularFactors(
        strict_lower.indptr.astype(np.int64),
        strict_lower.indices.astype(np.int64),
        np.ascontiguousarray(strict_lower.data, dtype=np.float64),
        strict_upper.indptr.astype(np.int64),
        strict_upper.indices.astype(np.int64),
        np.ascontiguousarray(strict_upper.data, dtype=np.float64),
        1.0 / diagonal,
    )


def solve_ordered(factors: TriangularFactors, rhs: np.ndarray, order: np.ndarray) -> np.ndarray:
    """``X`` [n, k] with ``A[order][:, order] X[order] = rhs[order]`` for ``rhs`` [n, k]: the
    solution of a system whose matrix was factorised in the elimination ``order`` [n], in the
    original order."""
    rhs = np.asarray(rhs, dtype=np.float64)
    n, k = rhs.shape
    # three columns per pass: their running sums stay in registers
    padded = np.zeros((n, 3 * -(-k // 3)))
    padded[:, :k] = rhs
    out = np.empty_like(padded)
    work = np.empty((n, 3))
    order = np.asarray(order, dtype=np.int64)
    f = factors
    for c in range(0, padded.shape[1], 3):
        _solve_ordered3(
            f.lower_indptr, f.lower_indices, f.lower_data, f.upper_indptr, f.upper_indices,
            f.upper_data, f.inverse_diagonal, padded[:, c : c + 3], order, work,
            out[:, c : c + 3],
        )
    return out[:, :k]


@numba.njit(cache=True, inline="always")
def _minus_row(indptr, indices, data, i, y, s0, s1, s2):
    """``(s0, s1, s2)`` less row ``i`` of the CSR factor times the three columns of ``y``."""
    for e in range(indptr[i], indptr[i + 1]):
        j = indices[e]
        v = data[e]
        s0 -= v * y[j, 0]
        s1 -= v * y[j, 1]
        s2 -= v * y[j, 2]
    return s0, s1, s2


@numba.njit(cache=True, nogil=True)
def _solve_ordered3(lp, li, lx, up, ui, ux, inverse, rhs, order, y, out):
    """Forward substitution with the unit lower factor, then backward with the upper one, the
    three columns of ``rhs`` [n, 3] per factor entry; ``y`` [n, 3] is scratch, ``out`` [n, 3]
    the result."""
    for i in range(len(inverse)):
        source = order[i]
        y[i, 0], y[i, 1], y[i, 2] = _minus_row(
            lp, li, lx, i, y, rhs[source, 0], rhs[source, 1], rhs[source, 2]
        )
    for i in range(len(inverse) - 1, -1, -1):
        s0, s1, s2 = _minus_row(up, ui, ux, i, y, y[i, 0], y[i, 1], y[i, 2])
        d = inverse[i]
        y[i, 0] = s0 * d
        y[i, 1] = s1 * d
        y[i, 2] = s2 * d
        target = order[i]
        out[target, 0] = y[i, 0]
        out[target, 1] = y[i, 1]
        out[target, 2] = y[i, 2]


def elimination_order(laplacian: sp.csr_matrix) -> np.ndarray:
    """A fill-reducing order [N] of the unknowns of a sparse symmetric matrix (its structure;
    the diagonal is ignored): METIS's nested dissection of its graph, computed once and reused
    by every factorisation with the same structure (kinematic's sliding: the reduced systems of
    every step, 2 or 3 unknowns per vertex; material-aware deformation's repositioning).

    Nested dissection rather than minimum degree: SuperLU's factorisation of the reduced
    system of a step took 67 instead of 95 ms on dfaust-hopping (20,430 unknowns) and 86
    instead of 145 ms on rigid-turn (20,088) in this order, with about as many nonzeros in
    the factors: its separators give SuperLU larger supernodes."""
    n = laplacian.shape[0]
    if n < 2:
        return np.arange(n)
    # the structure of L (explicit zeros too), symmetric, without the diagonal
    coo = sp.coo_matrix(laplacian)
    off = coo.row != coo.col
    if not off.any():
        return np.arange(n)
    rows, cols = np.concatenate([coo.row[off], coo.col[off]]), np.concatenate([coo.col[off], coo.row[off]])
    graph = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    graph.sort_indices()
    perm, _ = pymetis.nested_dissection(
        adjacency=pymetis.CSRAdjacency(
            graph.indptr.astype(np.int64), graph.indices.astype(np.int64)
        )
    )
    return np.asarray(perm, dtype=np.int64)
