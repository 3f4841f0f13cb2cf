"""Gauss-Seidel sweeps and products of the flow solver's V-cycle on all cores.

Why: the V-cycle's Gauss-Seidel sweeps run row after row on one core, and they were most of
a MINRES step (captured crane system at resolution 64, one solve of 40 steps, 15.3 s: the
finest level's sweeps 4.2 s, the coarse levels' 2.3 s, scipy's products 2.1 s).

How, without changing what Gauss-Seidel computes: every unknown of a flow system belongs to a
time slice (a free cell to its slice, a flow to its source's), and the system only couples
unknowns of nearby slices (the finest level: slices ``t`` and ``t + 1``; a coarse level a few
more, measured as its ``reach``). Rows are put in blocks of at least ``reach`` consecutive
slices (:data:`BLOCKS` of them), the blocks coloured alternately: two blocks of one colour
are more than ``reach`` slices apart, so they share no entry and their rows can be swept at
the same time, in any interleaving, with the same result. A sweep is then an ordinary Gauss-Seidel sweep in another row order
(colour by colour, block by block, rows in their own order within a block), computed in
parallel; the backward sweep is that order reversed, its adjoint, so the V-cycle stays
symmetric. The result does not depend on the number of threads.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.sparse_products import unsigned

#: Blocks of slices to aim for: two of each colour, one per core of the 2-core target
#: machine. Within a block the rows are swept in their own order, through its slices one
#: after the other, as the serial sweep goes: alternating single slices (red-black in
#: time) weakened the V-cycle (a 16-slice test system: MINRES residual after 60 steps
#: 1.8e-3 in the system's order, 4.0e-3 with one slice per block).
BLOCKS = 4
#: Fewer blocks than this: sweep serially.
MIN_BLOCKS = 4


class Schedule(NamedTuple):
    """A row order for parallel Gauss-Seidel.

    rows : unsigned int [n], the rows block by block, the blocks of colour 0 first.
    block_starts : int64 [blocks + 1], each block's range in ``rows``.
    colour_start : int, the first block of colour 1.
    """

    rows: np.ndarray
    block_starts: np.ndarray
    colour_start: int


@numba.njit(cache=True)
def _block_rows(groups, low, width, count, rows, starts):
    """Rows by (colour, block), each block's in their own order (a counting sort)."""
    for i in range(len(groups)):
        block = (groups[i] - low) // width
        starts[(block % 2) * count + block + 1] += 1
    for k in range(len(starts) - 1):
        starts[k + 1] += starts[k]
    at = starts[:-1].copy()
    for i in range(len(groups)):
        block = (groups[i] - low) // width
        key = (block % 2) * count + block
        rows[at[key]] = i
        at[key] += 1


def schedule(groups: np.ndarray, reach: int, blocks: int | None = None) -> Schedule | None:
    """The :class:`Schedule` of rows in time slices ``groups`` [n] (int) whose entries join
    rows at most ``reach`` slices apart: blocks of at least ``reach`` consecutive slices,
    about ``blocks`` of them (default :data:`BLOCKS`); None when that leaves fewer than
    :data:`MIN_BLOCKS`."""
    groups = np.asarray(groups)
    if len(groups) == 0:
        return None
    low = int(groups.min())
    span = int(groups.max()) - low + 1
    blocks = BLOCKS if blocks is None else blocks
    width = max(int(reach), -(-span // blocks), 1)
    count = (span - 1) // width + 1
    if count < MIN_BLOCKS:
        return None
    # colour 0 (even blocks) first, then colour 1; no n-sized temporary (the IRLS's later
    # set-ups run with the earlier hierarchy and the new system in memory)
    rows = np.empty(len(groups), np.uint32 if len(groups) < 2**32 else np.int64)
    starts = np.zeros(2 * count + 1, np.int64)
    _block_rows(groups, low, width, count, rows, starts)
    keys = np.concatenate([np.arange(0, count, 2), count + np.arange(1, count, 2)])
    block_starts = np.concatenate([[0], np.cumsum(np.diff(starts)[keys])]).astype(np.int64)
    return Schedule(rows, block_starts, (count + 1) // 2)


@numba.njit(cache=True)
def _csr_reach(indptr, indices, groups):
    reach = 0
    for i in range(len(indptr) - 1):
        gi = groups[i]
        for p in range(indptr[i], indptr[i + 1]):
            d = abs(groups[indices[p]] - gi)
            if d > reach:
                reach = d
    return reach


def csr_reach(A: sp.csr_matrix, groups: np.ndarray) -> int:
    """The largest slice distance ``|groups[i] - groups[j]|`` over the entries of ``A``."""
    return int(_csr_reach(unsigned(A.indptr), unsigned(A.indices), np.asarray(groups)))


@numba.njit(cache=True)
def _column_spans(indptr, indices, groups, columns):
    low = np.full(columns, np.iinfo(np.int64).max)
    high = np.full(columns, np.iinfo(np.int64).min)
    for i in range(len(indptr) - 1):
        g = groups[i]
        for p in range(indptr[i], indptr[i + 1]):
            c = indices[p]
            if g < low[c]:
                low[c] = g
            if g > high[c]:
                high[c] = g
    reach = 0
    for c in range(columns):
        if high[c] >= low[c] and high[c] - low[c] > reach:
            reach = high[c] - low[c]
    return reach


def normal_reach(A: sp.csr_matrix, C: sp.csr_matrix, groups: np.ndarray) -> int:
    """The slice reach of ``A + C C^T`` (``A`` [n, n], ``C`` [n, m] CSR): the larger of
    ``A``'s and the widest column of ``C`` (two rows sharing a column are joined)."""
    groups = np.asarray(groups)
    return max(
        csr_reach(A, groups), int(_column_spans(C.indptr, C.indices, groups, C.shape[1]))
    )


@numba.njit(cache=True)
def _coarse_groups(indptr, indices, data, groups, out):
    for i in range(len(indptr) - 1):
        for p in range(indptr[i], indptr[i + 1]):
            if out[indices[p]] < 0:
                out[indices[p]] = groups[i]
    for i in range(len(indptr) - 1):
        if indptr[i + 1] - indptr[i] == 1 and data[indptr[i]] == 1:
            out[indices[indptr[i]]] = groups[i]


def coarse_groups(P: sp.csr_matrix, groups: np.ndarray) -> np.ndarray:
    """The slice of each coarse unknown of interpolation ``P`` [n, coarse] (CSR): that of the
    fine row interpolated from it alone (a row whose only entry is 1: classical AMG's coarse
    points), else that of the first row that uses it (0 if none does)."""
    out = np.full(P.shape[1], -1, dtype=np.int64)
    _coarse_groups(unsigned(P.indptr), unsigned(P.indices), P.data, np.asarray(groups), out)
    out[out < 0] = 0
    return out


@numba.njit(cache=True, inline="always")
def normal_row(a_indptr, a_indices, a_data, c_indptr, c_indices, c_data, diagonal, x, y, rhs,
                i):
    """Gauss-Seidel's update of row ``i`` of ``(A + C C^T) x = rhs`` with ``y = C^T x`` [m]
    kept up to date (row ``i`` of ``S x`` is ``A_i x + C_i y``); rows with a zero diagonal
    are left alone."""
    if diagonal[i] == 0:
        return
    total = 0.0
    for p in range(a_indptr[i], a_indptr[i + 1]):
        total += a_data[p] * x[a_indices[p]]
    for p in range(c_indptr[i], c_indptr[i + 1]):
        total += c_data[p] * y[c_indices[p]]
    delta = (rhs[i] - total) / diagonal[i]
    x[i] += delta
    for p in range(c_indptr[i], c_indptr[i + 1]):
        y[c_indices[p]] += c_data[p] * delta


@numba.njit(cache=True, parallel=True)
def _normal_sweep_blocks(a_indptr, a_indices, a_data, c_indptr, c_indices, c_data, diagonal,
                         x, y, rhs, rows, block_starts, first_block, last_block, forward):
    for b in numba.prange(last_block - first_block):
        lo, hi = block_starts[first_block + b], block_starts[first_block + b + 1]
        if forward:
            for q in range(lo, hi):
                normal_row(a_indptr, a_indices, a_data, c_indptr, c_indices, c_data,
                            diagonal, x, y, rhs, rows[q])
        else:
            for q in range(hi - 1, lo - 1, -1):
                normal_row(a_indptr, a_indices, a_data, c_indptr, c_indices, c_data,
                            diagonal, x, y, rhs, rows[q])


def normal_sweep(A, C, diagonal, x, y, rhs, order: Schedule, *, forward: bool) -> None:
    """One Gauss-Seidel sweep of ``(A + C C^T) x = rhs`` in the row order of ``order``
    (reversed when not ``forward``), keeping ``y = C^T x`` up to date; ``x`` [n] and ``y``
    [m] are updated in place. Row ``i`` of ``(A + C C^T) x`` is ``A_i x + C_i y``."""
    arrays = (unsigned(A.indptr), unsigned(A.indices), A.data, unsigned(C.indptr),
              unsigned(C.indices), C.data, diagonal, x, y, rhs, order.rows, order.block_starts)
    blocks = len(order.block_starts) - 1
    colours = [(0, order.colour_start), (order.colour_start, blocks)]
    for first, last in colours if forward else colours[::-1]:
        _normal_sweep_blocks(*arrays, first, last, forward)


@numba.njit(cache=True, inline="always")
def _csr_row(indptr, indices, data, x, rhs, i):
    total = rhs[i]
    diagonal = data.dtype.type(0)
    for p in range(indptr[i], indptr[i + 1]):
        j = indices[p]
        if j == i:
            diagonal = data[p]
        else:
            total -= data[p] * x[j]
    if diagonal != 0:
        x[i] = total / diagonal


@numba.njit(cache=True, parallel=True)
def _csr_sweep_blocks(indptr, indices, data, x, rhs, rows, block_starts, first_block,
                      last_block, forward):
    for b in numba.prange(last_block - first_block):
        lo, hi = block_starts[first_block + b], block_starts[first_block + b + 1]
        if forward:
            for q in range(lo, hi):
                _csr_row(indptr, indices, data, x, rhs, rows[q])
        else:
            for q in range(hi - 1, lo - 1, -1):
                _csr_row(indptr, indices, data, x, rhs, rows[q])


def csr_sweep(A: sp.csr_matrix, x: np.ndarray, rhs: np.ndarray, order: Schedule, *,
              forward: bool) -> None:
    """One Gauss-Seidel sweep of ``A x = rhs`` (CSR) in the row order of ``order`` (reversed
    when not ``forward``), in place; rows with a zero diagonal are left alone (as pyamg's)."""
    if A.format != "csr":
        raise ValueError(f"csr_sweep needs a CSR matrix, got {A.format}")
    arrays = (unsigned(A.indptr), unsigned(A.indices), A.data, x, rhs, order.rows,
              order.block_starts)
    blocks = len(order.block_starts) - 1
    colours = [(0, order.colour_start), (order.colour_start, blocks)]
    for first, last in colours if forward else colours[::-1]:
        _csr_sweep_blocks(*arrays, first, last, forward)


#: Row chunks of :func:`transpose_multiply`, a fixed number so that its sums do not depend
#: on the number of cores.
TRANSPOSE_CHUNKS = 8


@numba.njit(cache=True, parallel=True)
def _csr_transpose_multiply(indptr, indices, data, x, bounds, partial):
    for c in numba.prange(len(bounds) - 1):
        row = partial[c]
        row[:] = 0
        for i in range(bounds[c], bounds[c + 1]):
            value = x[i]
            if value != 0:
                for p in range(indptr[i], indptr[i + 1]):
                    row[indices[p]] += data[p] * value


def transpose_multiply(
    P: sp.csr_matrix, x: np.ndarray, partial: np.ndarray | None = None
) -> np.ndarray:
    """``P.T @ x`` [m] for CSR ``P`` [n, m] and ``x`` [n], in the result type of both:
    :data:`TRANSPOSE_CHUNKS` row chunks scatter into their own rows of a work array
    (``partial`` [TRANSPOSE_CHUNKS, m] when given) in parallel, then the rows are added in
    order (the same sums on any number of cores)."""
    if P.format != "csr":
        raise ValueError(f"transpose_multiply needs a CSR matrix, got {P.format}")
    dtype = np.result_type(P.dtype, x.dtype)
    n = P.shape[0]
    bounds = np.linspace(0, n, TRANSPOSE_CHUNKS + 1).astype(np.int64)
    if partial is None:
        partial = np.empty((TRANSPOSE_CHUNKS, P.shape[1]), dtype)
    elif partial.shape != (TRANSPOSE_CHUNKS, P.shape[1]) or partial.dtype != dtype:
        raise ValueError(f"partial must be {dtype} [{TRANSPOSE_CHUNKS}, {P.shape[1]}]")
    _csr_transpose_multiply(unsigned(P.indptr), unsigned(P.indices), P.data, x, bounds, partial)
    return partial.sum(axis=0, dtype=dtype)
