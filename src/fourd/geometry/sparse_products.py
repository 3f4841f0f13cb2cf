"""Sparse matrix products on all cores: scipy's run on one.

:func:`csr_product` and :func:`galerkin_product` are Gustavson's row-by-row product (of
``R A P + D``, :func:`_triple_product`), rows split into chunks that run in parallel; each
thread keeps one dense marker of the output columns. Two passes: the row lengths (skipped
when an earlier product of the same patterns gave them), then the entries. Column indices within a row come in first-touch order (not sorted), as from scipy.
Every row is summed by one thread in a fixed order, so the results do not depend on the
number of cores. :func:`multiply_add` is the matrix-vector product, rows in parallel, and
:func:`symmetric_multiply` that of a symmetric matrix stored as its upper triangle.

Used by the flow solver (its AMG set-up is mostly products, ``B^T B`` and the Galerkin
products ``P^T A P`` of every level: about 20% of the flow stage at resolution 64) and by
``surfels``' Gauss-Newton (``J^T J`` and the conjugate gradients' products).
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

#: Chunks per thread (rows are uneven: the coarse levels are denser towards some rows).
CHUNKS_PER_THREAD = 8


def unsigned(index: np.ndarray) -> np.ndarray:
    """A 32-bit index array (of non-negative values) viewed as unsigned, for the compiled
    kernels: numba wraps a negative signed index around, a test and an add at every access,
    which made a Gauss-Seidel sweep in numba twice as slow as pyamg's C++ one (a coarse level
    of the captured crane system at resolution 64, 17M nonzeros: 20.6 ms against 10.6 ms,
    10.0 ms with unsigned indices). Other arrays are returned as they are (numba's
    arithmetic on unsigned and signed 64-bit integers goes through floats)."""
    if index.dtype == np.int32:
        return np.ascontiguousarray(index).view(np.uint32)
    return index


def unsigned_pattern(M: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    return unsigned(M.indptr), unsigned(M.indices)


@numba.njit(cache=True, inline="always")
def _add(i, col, value, end, limit, marker, at, c_indices, c_data):
    """Add ``value`` to entry ``col`` of row ``i``; a new entry goes to ``end``, or, at the
    row's ``limit`` already, to the spare last slot of ``c_indices`` and ``c_data`` (a row
    longer than its length: the caller refuses the result). Returns the next free position."""
    if marker[col] != i:
        marker[col] = i
        place = end if end < limit else len(c_data) - 1
        at[col] = place
        c_indices[place] = col
        c_data[place] = value
        return end + 1
    c_data[at[col]] += value
    return end


def _row_bounds(indptr: np.ndarray, chunks: int) -> np.ndarray:
    """Row ranges of about equal nonzero counts (``chunks + 1`` increasing bounds)."""
    n = len(indptr) - 1
    targets = np.linspace(0, indptr[-1], chunks + 1)
    bounds = np.searchsorted(indptr, targets, side="left")
    bounds[0], bounds[-1] = 0, n
    return np.unique(bounds).astype(np.int64)


def csr_product(
    a: sp.spmatrix,
    b: sp.spmatrix,
    add: sp.spmatrix | None = None,
    *,
    upper: bool = False,
    row_lengths: np.ndarray | None = None,
) -> sp.csr_matrix:
    """``a @ b`` (``+ add``) for sparse ``a`` [n, k], ``b`` [k, m] (and ``add`` [n, m]) as CSR,
    in the result type of their dtypes; explicit zeros from cancellation are kept (scipy's
    product drops them). ``upper``: only the entries on and above the diagonal (column >=
    row), as :func:`symmetric_multiply` takes a symmetric product such as ``a.T @ a``.

    ``row_lengths`` (int [n]): those of an earlier result (``np.diff(indptr)``, with the same
    ``upper``) of operands with the same sparsity patterns, values aside. They are taken
    instead of counted (a third of the product's time), and the entries come in the same
    places. Operands of other patterns are refused where a row's length differs.

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
    # I a b + add: one pass of the identity's single entry per row
    rows = np.arange(n + 1, dtype=a.indptr.dtype)
    identity = sp.csr_matrix((np.ones(n, dtype), rows[:-1], rows), shape=(n, n))
    if row_lengths is not None and np.shape(row_lengths) != (n,):
        raise ValueError(f"row_lengths must have shape [{n}], got {np.shape(row_lengths)}")
    return _triple_product(identity, a, b, add, dtype, a.indptr + add.indptr, upper, row_lengths)


@numba.njit(cache=True, inline="always")
def _new_column(col, row, marker, upper):
    """1 when column ``col`` is new to ``row`` (marked now) and kept (``upper``: ``col >=
    row``), else 0."""
    if (upper and col < row) or marker[col] == row:
        return 0
    marker[col] = row
    return 1


@numba.njit(cache=True, parallel=True)
def _triple_lengths(
    r_indptr, r_indices, a_indptr, a_indices, p_indptr, p_indices, d_indptr, d_indices,
    bounds, last_row, upper,
):
    """The row lengths of ``R A P + D`` (``upper``: its columns >= the row only)."""
    lengths = np.zeros(len(r_indptr) - 1, np.int64)
    for c in numba.prange(len(bounds) - 1):
        marker = last_row[numba.get_thread_id()]
        for row in range(bounds[c], bounds[c + 1]):
            count = 0
            for dd in range(d_indptr[row], d_indptr[row + 1]):
                count += _new_column(d_indices[dd], row, marker, upper)
            for ii in range(r_indptr[row], r_indptr[row + 1]):
                i = r_indices[ii]
                for kk in range(a_indptr[i], a_indptr[i + 1]):
                    k = a_indices[kk]
                    for pp in range(p_indptr[k], p_indptr[k + 1]):
                        count += _new_column(p_indices[pp], row, marker, upper)
            lengths[row] = count
    return lengths


@numba.njit(cache=True, parallel=True)
def _triple_fill(
    r_indptr, r_indices, r_data, a_indptr, a_indices, a_data, p_indptr, p_indices, p_data,
    d_indptr, d_indices, d_data, bounds, last_row, position, c_indptr, c_indices, c_data,
    upper, misfit,
):
    """The entries of ``R A P + D`` into rows of the lengths of :func:`_triple_lengths`
    (``c_indices`` and ``c_data`` one spare slot longer); ``misfit[chunk]`` set where a row's
    entries did not fill its length exactly (lengths from another product)."""
    for c in numba.prange(len(bounds) - 1):
        thread = numba.get_thread_id()
        # marker[col] == row: column col of this row is already at position[col]
        marker = last_row[thread]
        at = position[thread]
        for row in range(bounds[c], bounds[c + 1]):
            end = c_indptr[row]
            limit = c_indptr[row + 1]
            for dd in range(d_indptr[row], d_indptr[row + 1]):
                if upper and d_indices[dd] < row:
                    continue
                end = _add(
                    row, d_indices[dd], d_data[dd], end, limit, marker, at, c_indices, c_data
                )
            for ii in range(r_indptr[row], r_indptr[row + 1]):
                i = r_indices[ii]
                r = r_data[ii]
                for kk in range(a_indptr[i], a_indptr[i + 1]):
                    k = a_indices[kk]
                    ra = r * a_data[kk]
                    for pp in range(p_indptr[k], p_indptr[k + 1]):
                        if upper and p_indices[pp] < row:
                            continue
                        end = _add(
                            row, p_indices[pp], ra * p_data[pp], end, limit, marker, at,
                            c_indices, c_data,
                        )
            if end != limit:
                misfit[c] = True


def _triple_product(
    R, A, P, D, dtype, work: np.ndarray, upper: bool = False, lengths: np.ndarray | None = None
) -> sp.csr_matrix:
    """``R @ A @ P + D`` (CSR, shapes checked by the caller) in ``dtype``, rows split into
    chunks of about equal ``work`` (cumulative per row, [rows + 1]) that run in parallel;
    each thread keeps one dense marker of the output columns. Two passes: the row lengths
    (unless given, ``lengths`` [rows]), then the entries. ``upper``: the entries on and
    above the diagonal only."""
    rows, m = R.shape[0], P.shape[1]
    if rows == 0 or m == 0:
        return sp.csr_matrix((rows, m), dtype=dtype)
    threads = numba.get_num_threads()
    bounds = _row_bounds(work, CHUNKS_PER_THREAD * threads)
    # one marker per thread, allocated once here (not per chunk inside the worker threads,
    # whose malloc arenas keep what they freed)
    last_row = np.full((threads, m), -1, np.int64)
    if lengths is None:
        lengths = _triple_lengths(
            *unsigned_pattern(R), *unsigned_pattern(A), *unsigned_pattern(P),
            *unsigned_pattern(D), bounds, last_row, bool(upper),
        )
        last_row.fill(-1)
    indptr = np.zeros(rows + 1, np.int64)
    np.cumsum(lengths, out=indptr[1:])
    index_type = np.int32 if indptr[-1] < np.iinfo(np.int32).max and m < 2**31 else np.int64
    # one spare slot: where the entries past a wrong length go
    indices = np.empty(indptr[-1] + 1, index_type)
    data = np.empty(indptr[-1] + 1, dtype)
    misfit = np.zeros(len(bounds) - 1, dtype=np.bool_)
    _triple_fill(
        *unsigned_pattern(R), R.data.astype(dtype, copy=False),
        *unsigned_pattern(A), A.data.astype(dtype, copy=False),
        *unsigned_pattern(P), P.data.astype(dtype, copy=False),
        *unsigned_pattern(D), D.data.astype(dtype, copy=False),
        bounds, last_row, np.empty((threads, m), np.int64), indptr, indices, data, bool(upper),
        misfit,
    )
    if misfit.any():
        raise ValueError("row_lengths are not this product's: a row's entries differ")
    return sp.csr_matrix(
        (data[:-1], indices[:-1], indptr.astype(index_type, copy=False)), shape=(rows, m)
    )


def galerkin_product(R: sp.spmatrix, A: sp.spmatrix, P: sp.spmatrix) -> sp.csr_matrix:
    """``R @ A @ P`` for sparse ``R`` [nc, n], ``A`` [n, n], ``P`` [n, nc] as CSR, without
    the intermediate ``A @ P``: on squash-ball's first flow system at resolution 64 (7.9M
    unknowns, 121M nonzeros) ``A @ P`` alone held 135M nonzeros (1.1 GB), more than the
    result. Every entry is summed in one pass per output row (``((r a) p)``, so rounding
    differs from ``R @ (A @ P)``); explicit zeros are kept, as in :func:`csr_product`.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> a = sp.random(30, 30, density=0.2, random_state=0, format="csr")
    >>> p = sp.random(30, 8, density=0.3, random_state=1, format="csr")
    >>> bool(abs(galerkin_product(p.T, a, p) - p.T @ a @ p).max() < 1e-12)
    True
    """
    R, A, P = sp.csr_matrix(R), sp.csr_matrix(A), sp.csr_matrix(P)
    if R.shape[1] != A.shape[0] or A.shape[1] != P.shape[0]:
        raise ValueError(f"shapes {R.shape}, {A.shape} and {P.shape} do not match")
    dtype = np.result_type(R.dtype, A.dtype, P.dtype)
    # a coarse row's work is about its fine rows' nonzeros in A
    work = np.zeros(R.nnz + 1, np.int64)
    np.cumsum(np.diff(A.indptr)[R.indices], out=work[1:])
    nothing = sp.csr_matrix((R.shape[0], P.shape[1]), dtype=dtype)
    return _triple_product(R, A, P, nothing, dtype, work[R.indptr])


@numba.njit(cache=True, parallel=True)
def _csr_multiply_add(indptr, indices, data, x, out, scale):
    for i in numba.prange(len(out)):
        total = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            total += data[p] * x[indices[p]]
        out[i] += scale * total


def multiply_add(A: sp.csr_matrix, x: np.ndarray, out: np.ndarray, scale: float = 1.0) -> None:
    """``out += scale * A @ x`` for CSR ``A``, rows in parallel (``out`` in place)."""
    if A.format != "csr":
        raise ValueError(f"multiply_add needs a CSR matrix, got {A.format}")
    _csr_multiply_add(unsigned(A.indptr), unsigned(A.indices), A.data, x, out, scale)


#: Row chunks of :func:`symmetric_multiply`, a fixed number so that its sums do not depend on
#: the number of cores.
SYMMETRIC_CHUNKS = 8


@numba.njit(cache=True, parallel=True, nogil=True)
def _symmetric_multiply(indptr, indices, data, x, bounds, partial, out):
    for c in numba.prange(len(bounds) - 1):
        row = partial[c]
        row[:] = 0.0
        for i in range(bounds[c], bounds[c + 1]):
            xi = x[i]
            total = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                value = data[k]
                total += value * x[j]
                if j != i:
                    row[j] += value * xi
            row[i] += total
    for i in numba.prange(len(out)):
        total = 0.0
        for c in range(partial.shape[0]):
            total += partial[c, i]
        out[i] = total


def symmetric_multiply(
    upper: sp.csr_matrix,
    x: np.ndarray,
    out: np.ndarray | None = None,
    partial: np.ndarray | None = None,
) -> np.ndarray:
    """``A @ x`` [n] for the symmetric ``A`` [n, n] whose entries on and above the diagonal
    are the CSR ``upper`` (``csr_product(..., upper=True)``), into ``out`` when given.
    ``partial`` (float64 [:data:`SYMMETRIC_CHUNKS`, n]) is the work rows, for a caller that
    multiplies many times (a solver's iterations): allocated here when not given.

    Half the matrix read: on a 175,000-unknown Gauss-Newton system of ``surfels`` (28.4
    million nonzeros, 14.3 million in the upper triangle) 8.8 ms against 18.1 ms for
    :func:`multiply_add` on the whole matrix (2-core AMD EPYC). Each of
    :data:`SYMMETRIC_CHUNKS` row chunks adds the upper entries' transposes into a work row of
    its own; the rows are summed in order, so the result does not depend on the number of
    cores."""
    if upper.format != "csr":
        raise ValueError(f"symmetric_multiply needs a CSR matrix, got {upper.format}")
    n = upper.shape[0]
    if upper.shape != (n, n) or x.shape != (n,):
        raise ValueError(f"a square matrix and a vector of its size, got {upper.shape}, {x.shape}")
    bounds = _row_bounds(upper.indptr, SYMMETRIC_CHUNKS)
    if partial is None:
        partial = np.empty((SYMMETRIC_CHUNKS, n))
    elif partial.shape != (SYMMETRIC_CHUNKS, n) or partial.dtype != np.float64:
        raise ValueError(f"partial must be float64 [{SYMMETRIC_CHUNKS}, {n}]")
    out = np.empty(n) if out is None else out
    _symmetric_multiply(
        unsigned(upper.indptr), unsigned(upper.indices), np.asarray(upper.data, np.float64),
        np.asarray(x, np.float64), bounds, partial[: len(bounds) - 1], out,
    )
    return out


@numba.njit(cache=True, parallel=True, nogil=True)
def _column_counts(indptr, indices, bounds, counts):
    for c in numba.prange(len(bounds) - 1):
        row = counts[c]
        for i in range(bounds[c], bounds[c + 1]):
            for k in range(indptr[i], indptr[i + 1]):
                row[indices[k]] += 1


@numba.njit(cache=True, parallel=True, nogil=True)
def _transpose_fill(indptr, indices, data, bounds, cursor, out_indices, out_data):
    for c in numba.prange(len(bounds) - 1):
        at = cursor[c]
        for i in range(bounds[c], bounds[c + 1]):
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                place = at[j]
                out_indices[place] = i
                out_data[place] = data[k]
                at[j] = place + 1


def csr_transpose(matrix: sp.csr_matrix) -> sp.csr_matrix:
    """``matrix.T`` [m, n] as CSR for the CSR ``matrix`` [n, m], each row's columns
    increasing: ``matrix.T.tocsr()``'s result (the same arrays), its rows filled on all
    cores. Each thread's block of rows counts its entries per column, then writes them from
    where the blocks before it end."""
    if matrix.format != "csr":
        raise ValueError(f"csr_transpose needs a CSR matrix, got {matrix.format}")
    n, m = matrix.shape
    index = np.int32 if max(n, m, matrix.nnz) < np.iinfo(np.int32).max else np.int64
    bounds = _row_bounds(matrix.indptr, numba.get_num_threads())
    counts = np.zeros((len(bounds) - 1, m), np.int64)
    indptr, indices = unsigned_pattern(matrix)
    _column_counts(indptr, indices, bounds, counts)
    out_indptr = np.zeros(m + 1, np.int64)
    np.cumsum(counts.sum(axis=0), out=out_indptr[1:])
    # each block starts its column where the blocks before it end
    cursor = np.cumsum(counts, axis=0)
    cursor -= counts
    cursor += out_indptr[:-1]
    del counts
    out_indices = np.empty(matrix.nnz, index)
    out_data = np.empty(matrix.nnz, matrix.dtype)
    _transpose_fill(indptr, indices, matrix.data, bounds, cursor, out_indices, out_data)
    transposed = sp.csr_matrix((out_data, out_indices, out_indptr.astype(index)), shape=(m, n))
    transposed.has_sorted_indices = True
    return transposed
