"""Sparse matrix products on all cores, for the AMG set-up of the flow solver.

Why: scipy's sparse product runs on one core, and the set-up of the flow's V-cycle is mostly
products (``B^T B`` and the Galerkin products ``P^T A P`` of every level): about 20% of the
flow stage at resolution 64. :func:`csr_product` is Gustavson's row-by-row product, rows
split into chunks that run in parallel; each thread keeps one dense marker of the output
columns. Two passes: the row lengths, then the entries. Column indices within a row come in
first-touch order (not sorted), as from scipy.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

#: Chunks per thread (rows are uneven: the coarse levels are denser towards some rows).
CHUNKS_PER_THREAD = 8


@numba.njit(cache=True, parallel=True)
def _row_lengths(
    a_indptr, a_indices, b_indptr, b_indices, d_indptr, d_indices, bounds, last_row,
):
    lengths = np.zeros(len(a_indptr) - 1, np.int64)
    for c in numba.prange(len(bounds) - 1):
        marker = last_row[numba.get_thread_id()]
        for i in range(bounds[c], bounds[c + 1]):
            count = 0
            for dd in range(d_indptr[i], d_indptr[i + 1]):
                col = d_indices[dd]
                if marker[col] != i:
                    marker[col] = i
                    count += 1
            for jj in range(a_indptr[i], a_indptr[i + 1]):
                k = a_indices[jj]
                for kk in range(b_indptr[k], b_indptr[k + 1]):
                    col = b_indices[kk]
                    if marker[col] != i:
                        marker[col] = i
                        count += 1
            lengths[i] = count
    return lengths


@numba.njit(cache=True, inline="always")
def _add(i, col, value, end, marker, at, c_indices, c_data):
    """Add ``value`` to entry ``col`` of row ``i``; a new entry goes to ``end``. Returns the
    next free position."""
    if marker[col] != i:
        marker[col] = i
        at[col] = end
        c_indices[end] = col
        c_data[end] = value
        return end + 1
    c_data[at[col]] += value
    return end


@numba.njit(cache=True, parallel=True)
def _fill(
    a_indptr, a_indices, a_data, b_indptr, b_indices, b_data, d_indptr, d_indices, d_data,
    bounds, last_row, position, c_indptr, c_indices, c_data,
):
    for c in numba.prange(len(bounds) - 1):
        thread = numba.get_thread_id()
        # marker[col] == i: column col of row i is already at position[col]
        marker = last_row[thread]
        at = position[thread]
        for i in range(bounds[c], bounds[c + 1]):
            end = c_indptr[i]
            for dd in range(d_indptr[i], d_indptr[i + 1]):
                end = _add(i, d_indices[dd], d_data[dd], end, marker, at, c_indices, c_data)
            for jj in range(a_indptr[i], a_indptr[i + 1]):
                k = a_indices[jj]
                value = a_data[jj]
                for kk in range(b_indptr[k], b_indptr[k + 1]):
                    end = _add(
                        i, b_indices[kk], value * b_data[kk], end, marker, at, c_indices, c_data
                    )


def _row_bounds(indptr: np.ndarray, chunks: int) -> np.ndarray:
    """Row ranges of about equal nonzero counts (``chunks + 1`` increasing bounds)."""
    n = len(indptr) - 1
    targets = np.linspace(0, indptr[-1], chunks + 1)
    bounds = np.searchsorted(indptr, targets, side="left")
    bounds[0], bounds[-1] = 0, n
    return np.unique(bounds).astype(np.int64)


def csr_product(
    a: sp.spmatrix, b: sp.spmatrix, add: sp.spmatrix | None = None
) -> sp.csr_matrix:
    """``a @ b`` (``+ add``) for sparse ``a`` [n, k], ``b`` [k, m] (and ``add`` [n, m]) as CSR,
    in the result type of their dtypes; explicit zeros from cancellation are kept (scipy's
    product drops them).

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> a = sp.random(30, 20, density=0.2, random_state=0, format="csr")
    >>> b = sp.random(20, 25, density=0.2, random_state=1, format="csr")
    >>> bool(abs(csr_product(a, b) - a @ b).max() < 1e-12)
    True
    """
    a = sp.csr_matrix(a)
    b = sp.csr_matrix(b)
    n, m = a.shape[0], b.shape[1]
    if a.shape[1] != b.shape[0]:
        raise ValueError(f"shapes {a.shape} and {b.shape} do not match")
    if add is None:
        add = sp.csr_matrix((n, m), dtype=a.dtype)
    add = sp.csr_matrix(add)
    if add.shape != (n, m):
        raise ValueError(f"the addend's shape {add.shape} is not the product's {(n, m)}")
    dtype = np.result_type(a.dtype, b.dtype, add.dtype)
    if n == 0 or m == 0:
        return sp.csr_matrix((n, m), dtype=dtype)
    arrays = (
        a.indptr, a.indices, a.data.astype(dtype, copy=False),
        b.indptr, b.indices, b.data.astype(dtype, copy=False),
        add.indptr, add.indices, add.data.astype(dtype, copy=False),
    )
    threads = numba.get_num_threads()
    bounds = _row_bounds(a.indptr + add.indptr, CHUNKS_PER_THREAD * threads)
    # one marker per thread, allocated once here (not per chunk inside the worker threads,
    # whose malloc arenas keep what they freed)
    last_row = np.full((threads, m), -1, np.int64)
    lengths = _row_lengths(*arrays[0:2], *arrays[3:5], *arrays[6:8], bounds, last_row)
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(lengths, out=indptr[1:])
    index_type = np.int32 if indptr[-1] < np.iinfo(np.int32).max and m < 2**31 else np.int64
    indices = np.empty(indptr[-1], index_type)
    data = np.empty(indptr[-1], dtype)
    last_row.fill(-1)
    _fill(*arrays, bounds, last_row, np.empty((threads, m), np.int64), indptr, indices, data)
    return sp.csr_matrix((data, indices, indptr.astype(index_type, copy=False)), shape=(n, m))


def csr_from_rows(columns: np.ndarray, values: np.ndarray, n_cols: int) -> sp.csr_matrix:
    """The CSR matrix [r, n_cols] whose row ``i`` holds ``values[i, j]`` at ``columns[i, j]``
    for every slot ``j`` with ``columns[i, j] >= 0`` (a row table ``[r, w]``, at most ``w``
    entries per row, ``-1`` for an empty slot; slots in the order they should be stored).

    Examples
    --------
    >>> import numpy as np
    >>> csr_from_rows(np.array([[0, 2], [-1, 1]]), np.array([[1.0, 2.0], [9.0, 3.0]]), 3).toarray()
    array([[1., 0., 2.],
           [0., 3., 0.]])
    """
    present = columns >= 0
    indptr = np.zeros(len(columns) + 1, dtype=np.int64)
    np.cumsum(present.sum(axis=1), out=indptr[1:])
    return sp.csr_matrix((values[present], columns[present], indptr), shape=(len(columns), n_cols))
