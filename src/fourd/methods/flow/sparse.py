"""The other sparse kernels of the AMG set-up of the flow solver (its products are
:mod:`fourd.geometry.sparse_products`): strong connections, truncation, transposed patterns,
assembly from entries and submatrices, compiled and without scipy's intermediate copies.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.sparse_products import unsigned_pattern


@numba.njit(cache=True, parallel=True)
def _strong_rows(indptr, indices, data, theta, out_indptr, out_indices, out_data, step):
    """Row ``i``'s strong connections: step 0 counts them (into ``out_indptr[i + 1]``),
    step 1 stores their columns from ``out_indptr[i]``, increasing (the RS splitting's
    choices depend on the order, and pyamg's reach it sorted), step 2 their values at the
    stored columns' places."""
    for i in numba.prange(len(indptr) - 1):
        biggest = 0.0
        for jj in range(indptr[i], indptr[i + 1]):
            if indices[jj] != i:
                biggest = max(biggest, abs(data[jj]))
        threshold = theta * biggest
        start = out_indptr[i] if step > 0 else 0
        end = start
        for jj in range(indptr[i], indptr[i + 1]):
            value = data[jj]
            if indices[jj] != i and value != 0 and abs(value) >= threshold:
                if step == 1:
                    out_indices[end] = indices[jj]
                elif step == 2:
                    row = out_indices[start : out_indptr[i + 1]]
                    out_data[start + np.searchsorted(row, indices[jj])] = value
                end += 1
        if step == 0:
            out_indptr[i + 1] = end
        elif step == 1:
            out_indices[start:end] = np.sort(out_indices[start:end])


def strong_pattern(A: sp.spmatrix, theta: float) -> tuple[np.ndarray, np.ndarray]:
    """The classical (Ruge-Stueben) strong connections of ``A`` [n, n] (CSR): entry
    ``j != i`` of row ``i`` when ``a_ij != 0`` and ``|a_ij| >= theta max_{k != i} |a_ik|``,
    as a CSR pattern ``(indptr, indices)`` without values (``A``'s index type, each row's
    columns increasing, no diagonal).

    The pattern of ``pyamg.strength.classical_strength_of_connection(A, theta)`` (norm
    ``"abs"``) less its diagonal: what pyamg's RS splitting takes, after copying it twice
    (``remove_diagonal`` through COO, the transpose with values). With
    :func:`strong_values`, what its direct interpolation takes (after ``C.multiply(A)``,
    another copy)."""
    # the three calls of _strong_rows take one signature (each other signature is a compile)
    indptr = np.zeros(A.shape[0] + 1, np.int64)
    no_data = np.empty(0, A.dtype)
    no_indices = np.empty(0, A.indices.dtype)
    _strong_rows(*unsigned_pattern(A), A.data, theta, indptr, no_indices, no_data, 0)
    np.cumsum(indptr, out=indptr)
    indices = np.empty(indptr[-1], A.indices.dtype)
    _strong_rows(*unsigned_pattern(A), A.data, theta, indptr, indices, no_data, 1)
    return indptr.astype(A.indptr.dtype, copy=False), indices


def strong_values(A: sp.spmatrix, theta: float, indptr: np.ndarray, indices: np.ndarray):
    """``A``'s values [nnz] at the strong pattern ``(indptr, indices)`` of
    :func:`strong_pattern` (the same ``A`` and ``theta``)."""
    data = np.empty(len(indices), A.dtype)
    indptr = np.asarray(indptr, dtype=np.int64)
    indices = np.asarray(indices, dtype=A.indices.dtype)
    _strong_rows(*unsigned_pattern(A), A.data, theta, indptr, indices, data, 2)
    return data


@numba.njit(cache=True, parallel=True)
def _largest_in_rows(indptr, data, entries, keep):
    for i in numba.prange(len(indptr) - 1):
        start, stop = indptr[i], indptr[i + 1]
        for _ in range(min(entries, stop - start)):
            best, at = -1.0, -1
            for jj in range(start, stop):
                if not keep[jj] and abs(data[jj]) > best:
                    best, at = abs(data[jj]), jj
            keep[at] = True


def truncate_rows(P: sp.spmatrix, entries: int) -> sp.csr_matrix:
    """``P`` [n, m] with only the ``entries`` largest-magnitude entries of each row (the
    first of equal ones), scaled so that every row keeps its sum (where the kept entries'
    sum is not 0): interpolation truncation, as in hypre's ``P_max_elmts``.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> truncate_rows(sp.csr_matrix(np.array([[0.5, 0.3, 0.2], [0.0, 1.0, 0.0]])), 1).toarray()
    array([[1., 0., 0.],
           [0., 1., 0.]])
    """
    P = sp.csr_matrix(P)
    keep = np.zeros(P.nnz, bool)
    _largest_in_rows(P.indptr, P.data, entries, keep)
    rows = np.repeat(np.arange(P.shape[0]), np.diff(P.indptr))
    total = np.bincount(rows, P.data, minlength=P.shape[0])
    kept = np.bincount(rows[keep], P.data[keep], minlength=P.shape[0])
    scale = np.divide(total, kept, out=np.ones_like(total), where=kept != 0)
    counts = np.bincount(rows[keep], minlength=P.shape[0])
    indptr = np.zeros(P.shape[0] + 1, P.indptr.dtype)
    np.cumsum(counts, out=indptr[1:])
    data = (P.data[keep] * scale[rows[keep]]).astype(P.dtype)
    return sp.csr_matrix((data, P.indices[keep], indptr), shape=P.shape)


@numba.njit(cache=True)
def _transpose_pattern(indptr, indices, out_indptr, out_indices):
    for jj in range(len(indices)):
        out_indptr[indices[jj] + 2] += 1
    for j in range(2, len(out_indptr)):
        out_indptr[j] += out_indptr[j - 1]
    for i in range(len(indptr) - 1):
        for jj in range(indptr[i], indptr[i + 1]):
            j = indices[jj] + 1
            out_indices[out_indptr[j]] = i
            out_indptr[j] += 1


def transpose_pattern(
    indptr: np.ndarray, indices: np.ndarray, n_cols: int
) -> tuple[np.ndarray, np.ndarray]:
    """The CSR pattern ``(indptr, indices)`` of the transpose [n_cols, n] of the CSR pattern
    ``(indptr, indices)`` [n, n_cols], without values, each row's columns increasing (what
    ``A.T.tocsr()`` gives, at a third of its memory)."""
    out_indptr = np.zeros(n_cols + 2, indptr.dtype)
    out_indices = np.empty(len(indices), indices.dtype)
    _transpose_pattern(indptr, indices, out_indptr, out_indices)
    return out_indptr[:-1].copy(), out_indices


@numba.njit(cache=True)
def _scatter_entries(rows, columns, values, n_cols, cursor, out_indices, out_data):
    """Scatter the entries into their rows; returns the first entry whose column is out of
    range (nothing written for it or after it), -1 if none."""
    for k in range(len(rows)):
        r = rows[k]
        if r >= 0:
            c = columns[k]
            if c < 0 or c >= n_cols:
                return k
            at = cursor[r]
            out_indices[at] = c
            out_data[at] = values[k]
            cursor[r] = at + 1
    return -1


def csr_from_entries(
    rows: np.ndarray, columns: np.ndarray, values: np.ndarray, shape: tuple[int, int]
) -> sp.csr_matrix:
    """The CSR matrix [shape] with ``values[k]`` at ``(rows[k], columns[k])`` for every
    ``k`` with ``rows[k] >= 0`` (positions distinct: nothing is summed), each row's entries in
    the order given, with 32-bit indices where they fit.

    One counting sort (row lengths, then a scatter), so the only memory besides the result
    is one cursor per row; scipy's COO conversion copies the triplets and sorts every row.

    Examples
    --------
    >>> import numpy as np
    >>> csr_from_entries(np.array([1, 0, -1, 1]), np.array([2, 1, 0, 0]),
    ...                  np.array([1.0, 2.0, 9.0, 3.0]), (2, 3)).toarray()
    array([[0., 2., 0.],
           [3., 0., 1.]])
    """
    n_rows, n_cols = shape
    present = rows >= 0
    counts = np.bincount(rows[present], minlength=n_rows)
    if len(counts) > n_rows:
        raise ValueError(f"a row index is outside the shape {shape}")
    index = np.int32 if max(n_rows, n_cols, len(rows)) < np.iinfo(np.int32).max else np.int64
    indptr = np.zeros(n_rows + 1, dtype=index)
    np.cumsum(counts, out=indptr[1:])
    del counts, present
    indices = np.empty(indptr[-1], dtype=index)
    data = np.empty(indptr[-1], dtype=values.dtype)
    cursor = indptr[:-1].astype(np.int64)
    bad = _scatter_entries(rows, columns, values, n_cols, cursor, indices, data)
    if bad >= 0:
        raise ValueError(f"column {columns[bad]} of entry {bad} is outside the shape {shape}")
    return sp.csr_matrix((data, indices, indptr), shape=shape)


@numba.njit(cache=True)
def _submatrix_lengths(indptr, indices, rows, new_column, lengths):
    for r in range(len(rows)):
        row = rows[r]
        count = 0
        for p in range(indptr[row], indptr[row + 1]):
            if new_column[indices[p]] >= 0:
                count += 1
        lengths[r + 1] = count


@numba.njit(cache=True)
def _gather_rows(indptr, indices, data, rows, new_column, out_indptr, out_indices, out_data):
    """Rows ``rows`` and the columns with ``new_column >= 0``, renumbered, written one after
    the other into ``out_*`` (``out_indptr`` [len(rows) + 1] filled too). The output may be
    ``indices`` and ``data`` themselves when ``rows`` increase: a kept entry is never written
    past the position it is read from."""
    at = 0
    for r in range(len(rows)):
        row = rows[r]
        for p in range(indptr[row], indptr[row + 1]):
            column = new_column[indices[p]]
            if column >= 0:
                out_indices[at] = column
                out_data[at] = data[p]
                at += 1
        out_indptr[r + 1] = at


def submatrix(A: sp.spmatrix, rows: np.ndarray, columns: np.ndarray) -> sp.csr_matrix:
    """``A[rows][:, columns]`` of a CSR matrix ``A`` [n, m] for distinct ``rows`` [r] (any
    order) and sorted, distinct ``columns`` [c], in two passes over the kept rows (lengths,
    then entries) and with 32-bit indices where they fit: no intermediate copy, where
    scipy's row slice copies ``A``'s rows before its column slice copies them again."""
    A = sp.csr_matrix(A)
    rows = np.asarray(rows, dtype=np.int64)
    new_column = np.full(A.shape[1], -1, dtype=np.int64)
    new_column[np.asarray(columns, dtype=np.int64)] = np.arange(len(columns))
    lengths = np.zeros(len(rows) + 1, dtype=np.int64)
    _submatrix_lengths(*unsigned_pattern(A), rows, new_column, lengths)
    indptr = np.cumsum(lengths)
    del lengths
    index = np.int32 if max(indptr[-1], len(rows), len(columns)) < np.iinfo(np.int32).max else np.int64
    indices = np.empty(indptr[-1], dtype=index)
    data = np.empty(indptr[-1], dtype=A.dtype)
    _gather_rows(*unsigned_pattern(A), A.data, rows, new_column, indptr, indices, data)
    return sp.csr_matrix(
        (data, indices, indptr.astype(index, copy=False)), shape=(len(rows), len(columns))
    )


def principal_submatrix(
    A: sp.spmatrix, keep: np.ndarray, *, overwrite: bool = False
) -> sp.csr_matrix:
    """``A[keep][:, keep]`` of a square CSR matrix ``A`` [n, n] for sorted, distinct ``keep``
    [k] (:func:`submatrix`).

    With ``overwrite`` (``A`` CSR already), the entries are compacted within ``A``'s own
    arrays, which the result then shares and ``A`` is no longer valid: no second copy of a
    matrix that is about to be dropped (the first coarse level of squash-ball at resolution
    64 is 0.65 GiB)."""
    if not (overwrite and sp.isspmatrix_csr(A)):
        return submatrix(A, keep, keep)
    keep = np.asarray(keep, dtype=np.int64)
    if len(keep) > 1 and not (np.diff(keep) > 0).all():
        raise ValueError("keep must be sorted and distinct")
    new_column = np.full(A.shape[0], -1, dtype=np.int64)
    new_column[keep] = np.arange(len(keep))
    indptr = np.zeros(len(keep) + 1, dtype=A.indices.dtype)
    _gather_rows(A.indptr, A.indices, A.data, keep, new_column, indptr, A.indices, A.data)
    nnz = int(indptr[-1])
    return sp.csr_matrix(
        (A.data[:nnz], A.indices[:nnz], indptr), shape=(len(keep), len(keep)), copy=False
    )


@numba.njit(cache=True, inline="always")
def _is_weak(i, j, value, diagonal, theta):
    return j != i and abs(value) < theta * np.sqrt(abs(diagonal[i] * diagonal[j]))


@numba.njit(cache=True)
def _strong_counts(indptr, indices, data, diagonal, theta, lengths):
    """Entries kept per row (``lengths[i + 1]``); returns the first row with no diagonal
    entry, -1 if none."""
    for i in range(len(indptr) - 1):
        has_diagonal = False
        count = 0
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            has_diagonal |= j == i
            if not _is_weak(i, j, data[p], diagonal, theta):
                count += 1
        if not has_diagonal:
            return i
        lengths[i + 1] = count
    return -1


@numba.njit(cache=True)
def _strong_fill(indptr, indices, data, diagonal, theta, out_indptr, out_indices, out_data):
    for i in range(len(indptr) - 1):
        at = out_indptr[i]
        lumped = 0.0
        own = -1
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            if _is_weak(i, j, data[p], diagonal, theta):
                lumped += abs(data[p])
                continue
            if j == i:
                own = at
            out_indices[at] = j
            out_data[at] = data[p]
            at += 1
        out_data[own] += lumped


def drop_weak_entries(A: sp.spmatrix, theta: float) -> sp.csr_matrix:
    """``A`` [n, n] (symmetric, with a positive diagonal) without its off-diagonal entries
    ``|a_ij| < theta sqrt(a_ii a_jj)``, each dropped ``|a_ij|`` added to ``a_ii``.

    The change is ``A' - A = L - E`` with ``E`` the dropped entries and ``L`` the diagonal of
    their row sums of magnitudes, a diagonally dominant, so positive semidefinite, matrix:
    ``A'`` is at least as positive definite as ``A``. For sparser coarse levels of the
    V-cycle (a non-Galerkin coarse matrix; the V-cycle stays symmetric positive definite)."""
    A = sp.csr_matrix(A)
    diagonal = A.diagonal()
    lengths = np.zeros(A.shape[0] + 1, dtype=np.int64)
    bad = _strong_counts(A.indptr, A.indices, A.data, diagonal, float(theta), lengths)
    if bad >= 0:
        raise ValueError(f"row {bad} has no diagonal entry")
    indptr = np.cumsum(lengths).astype(A.indptr.dtype)
    del lengths
    indices = np.empty(indptr[-1], dtype=A.indices.dtype)
    data = np.empty(indptr[-1], dtype=A.dtype)
    _strong_fill(A.indptr, A.indices, A.data, diagonal, float(theta), indptr, indices, data)
    return sp.csr_matrix((data, indices, indptr), shape=A.shape)


@numba.njit(cache=True)
def _mark_columns(indptr, indices, rows, used):
    for r in range(len(rows)):
        row = rows[r]
        for p in range(indptr[row], indptr[row + 1]):
            used[indices[p]] = True


def used_columns(A: sp.spmatrix, rows: np.ndarray) -> np.ndarray:
    """Sorted indices of the columns of CSR ``A`` [n, m] with an entry in any of ``rows``."""
    A = sp.csr_matrix(A)
    used = np.zeros(A.shape[1], dtype=bool)
    _mark_columns(*unsigned_pattern(A), np.asarray(rows, dtype=np.int64), used)
    return np.flatnonzero(used)
