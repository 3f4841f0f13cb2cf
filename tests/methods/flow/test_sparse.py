"""The flow solver's sparse kernels against scipy."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from fourd.methods.flow.sparse import (
    csr_from_entries,
    principal_submatrix,
    strong_pattern,
    strong_values,
    submatrix,
    transpose_pattern,
    truncate_rows,
    used_columns,
)


def test_submatrices_match_scipy_slicing():
    matrix = sp.random(400, 400, density=0.03, random_state=3, format="csr", dtype=np.float32)
    keep = np.sort(np.random.default_rng(1).choice(400, 150, replace=False))
    sub = principal_submatrix(matrix, keep)
    assert sub.shape == (150, 150) and sub.dtype == np.float32
    assert abs(sub - matrix[keep][:, keep]).max() == 0
    assert principal_submatrix(matrix, np.zeros(0, dtype=np.int64)).shape == (0, 0)
    in_place = principal_submatrix(matrix.copy(), keep, overwrite=True)
    assert in_place.dtype == np.float32 and abs(in_place - sub).max() == 0
    rows = np.random.default_rng(2).permutation(400)[:90]  # any order, as an IRLS step gives
    columns = used_columns(matrix, rows)
    assert set(columns) == set(matrix[rows].indices) and (np.diff(columns) > 0).all()
    rectangular = submatrix(matrix, rows, columns)
    assert rectangular.shape == (90, len(columns))
    assert abs(rectangular - matrix[rows][:, columns]).max() == 0


def test_csr_from_entries_matches_scipy_coo():
    """The counting-sort assembly: scipy's matrix from the same triplets, entries of a row in
    the order given, rows ``-1`` skipped, 32-bit indices, and an entry outside the shape named."""
    rng = np.random.default_rng(3)
    positions = rng.choice(300 * 200, 2000, replace=False)
    rows, columns = positions // 200, positions % 200
    values = rng.normal(size=2000)
    rows[::9] = -1
    matrix = csr_from_entries(rows, columns, values, (300, 200))
    kept = rows >= 0
    expected = sp.coo_matrix((values[kept], (rows[kept], columns[kept])), shape=(300, 200))
    assert matrix.shape == (300, 200) and matrix.indices.dtype == np.int32
    assert matrix.nnz == kept.sum() and abs(matrix - expected).max() == 0
    first_row = np.flatnonzero(rows == rows[kept][0])
    start = matrix.indptr[rows[kept][0]]
    assert list(matrix.indices[start : start + len(first_row)]) == list(columns[first_row])
    with pytest.raises(ValueError, match="column 200 of entry 1"):
        csr_from_entries(np.array([0, 1]), np.array([0, 200]), np.ones(2), (300, 200))
    with pytest.raises(ValueError, match="row index"):
        csr_from_entries(np.array([300]), np.array([0]), np.ones(1), (300, 200))


def test_strong_connections_and_transpose_pattern_match_scipy():
    """The set-up kernels of the V-cycle's hierarchy: the classical strong connections
    (pyamg's pattern less the diagonal, A's values, columns increasing), the truncation and a
    values-free transpose."""
    from pyamg.strength import classical_strength_of_connection

    rng = np.random.default_rng(1)
    a = sp.random(600, 600, density=0.02, random_state=4, format="csr")
    a = (a + a.T + sp.diags(rng.random(600) + 1.0)).tocsr()
    a.indices = a.indices.copy()
    for i in range(0, 600, 7):  # unsorted rows, as the parallel products give them
        a.indices[a.indptr[i] : a.indptr[i + 1]] = a.indices[a.indptr[i] : a.indptr[i + 1]][::-1]
        a.data[a.indptr[i] : a.indptr[i + 1]] = a.data[a.indptr[i] : a.indptr[i + 1]][::-1]
    a.has_sorted_indices = False
    p = sp.random(600, 90, density=0.03, random_state=5, format="csr")
    strong_indptr, strong_indices = strong_pattern(a, 0.25)
    strong = sp.csr_matrix(
        (strong_values(a, 0.25, strong_indptr, strong_indices), strong_indices, strong_indptr),
        shape=a.shape,
    )
    reference = classical_strength_of_connection(sp.csr_matrix(a), theta=0.25).tocsr()
    reference.setdiag(0)
    reference.eliminate_zeros()
    reference.sort_indices()
    assert np.array_equal(strong.indptr, reference.indptr)
    assert np.array_equal(strong.indices, reference.indices)
    assert np.all(strong.diagonal() == 0)
    assert np.array_equal(strong.data, np.asarray(sp.csr_matrix(a)[strong.nonzero()]).ravel())
    assert all(np.all(np.diff(strong.indices[strong.indptr[i] : strong.indptr[i + 1]]) > 0)
               for i in range(600))

    indptr, indices = transpose_pattern(strong.indptr, strong.indices, 600)
    transposed = strong.T.tocsr()
    assert np.array_equal(indptr, transposed.indptr)
    assert np.array_equal(indices, transposed.indices)

    for entries in (1, 2):
        truncated = truncate_rows(p, entries)
        counts = np.diff(truncated.indptr)
        assert np.array_equal(counts, np.minimum(np.diff(p.indptr), entries))
        assert np.allclose(truncated.sum(axis=1), p.sum(axis=1))
        kept = np.asarray(abs(truncated).max(axis=1).todense()).ravel()
        assert np.allclose(kept > 0, np.asarray(abs(p).max(axis=1).todense()).ravel() > 0)
        # the kept columns are each row's largest
        rows = np.repeat(np.arange(p.shape[0]), counts)
        assert np.all(abs(p[rows, truncated.indices]).A1 >= np.sort(abs(p).toarray(), axis=1)[rows, -entries] - 1e-15)
