"""The parallel sparse products (:mod:`fourd.geometry.sparse_products`) against scipy."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import scipy.sparse as sp

from fourd.geometry.sparse_products import (
    SYMMETRIC_CHUNKS,
    csr_product,
    csr_transpose,
    galerkin_product,
    multiply_add,
    symmetric_multiply,
)


def test_csr_product_matches_scipy():
    """The parallel sparse product: the same matrix as scipy's, also with empty rows and
    columns, mixed precisions and more rows than one chunk each."""
    rng = np.random.default_rng(0)
    a = sp.random(3000, 400, density=0.01, random_state=1, format="csr")
    b = sp.random(400, 2500, density=0.02, random_state=2, format="csr").astype(np.float32)
    a = sp.csr_matrix(a.multiply(rng.random(a.shape[0])[:, None] > 0.2))  # empty rows
    a.eliminate_zeros()
    product = csr_product(a, b)
    expected = (a @ b).tocsr()
    assert product.shape == expected.shape and product.dtype == np.float64
    assert abs(product - expected).max() <= 1e-6 * abs(expected).max()
    assert product.nnz == expected.nnz  # random data: no cancellation to an explicit zero
    symmetric = csr_product(b.T, b)
    assert symmetric.dtype == np.float32
    assert abs(symmetric - (b.T @ b)).max() <= 1e-5 * abs(symmetric).max()
    assert csr_product(sp.csr_matrix((5, 4)), sp.csr_matrix((4, 3))).nnz == 0
    with pytest.raises(ValueError, match="do not match"):
        csr_product(a, a)
    addend = sp.random(2500, 2500, density=0.001, random_state=3, format="csr")
    fused = csr_product(b.T, b, add=addend)
    assert abs(fused - (b.T @ b + addend)).max() <= 1e-5 * abs(fused).max()
    with pytest.raises(ValueError, match="addend"):
        csr_product(b.T, b, add=a)


def test_galerkin_product_matches_scipy():
    """``R A P`` without ``A P``, on a symmetric ``A`` whose rows are partly unsorted."""
    rng = np.random.default_rng(1)
    a = sp.random(600, 600, density=0.02, random_state=4, format="csr")
    a = (a + a.T + sp.diags(rng.random(600) + 1.0)).tocsr()
    a.indices = a.indices.copy()
    for i in range(0, 600, 7):  # unsorted rows, as csr_product gives them
        a.indices[a.indptr[i] : a.indptr[i + 1]] = a.indices[a.indptr[i] : a.indptr[i + 1]][::-1]
        a.data[a.indptr[i] : a.indptr[i + 1]] = a.data[a.indptr[i] : a.indptr[i + 1]][::-1]
    a.has_sorted_indices = False
    p = sp.random(600, 90, density=0.03, random_state=5, format="csr")
    product = galerkin_product(p.T, a, p)
    expected = (p.T @ a @ p).tocsr()
    assert product.shape == (90, 90)
    assert abs(product - expected).max() <= 1e-12 * abs(expected).max()
    assert galerkin_product(sp.csr_matrix((3, 5)), sp.csr_matrix((5, 5)), sp.csr_matrix((5, 3))).nnz == 0
    with pytest.raises(ValueError, match="do not match"):
        galerkin_product(p, a, p)


def _on_one_thread_and_all(run):
    """``run()``'s results with one numba thread and with all of them."""
    results = []
    previous = numba.get_num_threads()
    try:
        for threads in (1, previous):
            numba.set_num_threads(threads)
            results.append(run())
    finally:
        numba.set_num_threads(previous)
    return results


def _product_and_multiplication(b, x):
    out = np.zeros(b.shape[0])
    multiply_add(b, x, out)
    return csr_product(b.T.tocsr(), b), out


def test_products_do_not_depend_on_the_number_of_threads():
    """Each row is summed by one thread in one order: the same bits on one core and on all."""
    b = sp.random(2000, 1500, density=0.01, random_state=6, format="csr")
    x = np.random.default_rng(2).standard_normal(1500)
    (one, out_one), (all_, out_all) = _on_one_thread_and_all(
        lambda: _product_and_multiplication(b, x)
    )
    assert np.array_equal(one.indptr, all_.indptr) and np.array_equal(one.indices, all_.indices)
    assert np.array_equal(one.data, all_.data) and np.array_equal(out_one, out_all)


def test_multiply_add_matches_scipy():
    rng = np.random.default_rng(1)
    P = sp.random(300, 40, density=0.1, random_state=2, format="csr", dtype=np.float32)
    x = rng.standard_normal(300)
    out = rng.standard_normal(300)
    expected = out - 2.0 * (P @ x[:40])
    multiply_add(P, x[:40], out, -2.0)
    assert np.allclose(out, expected, rtol=0, atol=1e-10)
    with pytest.raises(ValueError, match="CSR"):
        multiply_add(P.tocsc(), x[:40], out)


def test_the_upper_triangle_of_a_symmetric_product_and_its_multiplication():
    """``a.T @ a`` kept on and above the diagonal, and the symmetric product read from it: the
    whole matrix's, on one core and on all to the last bit."""
    a = sp.random(3000, 700, density=0.01, random_state=7, format="csr")
    full = (a.T @ a).tocsr()
    upper = csr_product(a.T.tocsr(), a, upper=True)
    assert sp.tril(upper, k=-1).nnz == 0
    assert abs(upper - sp.triu(full)).max() <= 1e-12 * abs(full).max()
    added = csr_product(a.T.tocsr(), a, add=sp.eye(700, format="csr") * 3.0, upper=True)
    assert abs(added - sp.triu(full + 3.0 * sp.eye(700))).max() <= 1e-12 * abs(full).max()
    x = np.random.default_rng(3).standard_normal(700)
    results = _on_one_thread_and_all(lambda: symmetric_multiply(upper, x))
    assert np.array_equal(results[0], results[1])
    assert np.allclose(results[0], full @ x, rtol=0, atol=1e-12 * abs(full @ x).max())
    out = np.empty(700)
    assert symmetric_multiply(upper, x, out) is out and np.array_equal(out, results[0])
    # work rows handed in, full of earlier values: the same product
    partial = np.full((SYMMETRIC_CHUNKS, 700), 7.0)
    assert np.array_equal(symmetric_multiply(upper, x, None, partial), results[0])
    with pytest.raises(ValueError, match="partial"):
        symmetric_multiply(upper, x, None, partial[:, :10])
    with pytest.raises(ValueError, match="square"):
        symmetric_multiply(upper, x[:10])


def test_the_transpose_is_scipys():
    """Rows of increasing columns, the same arrays as ``a.T.tocsr()``, also with empty rows
    and columns and rows that are not sorted."""
    a = sp.random(5000, 900, density=0.004, random_state=8, format="csr")
    a = sp.csr_matrix(a.multiply(np.arange(5000)[:, None] % 7 != 0))
    a.indices[a.indptr[3] : a.indptr[4]] = a.indices[a.indptr[3] : a.indptr[4]][::-1]
    a.has_sorted_indices = False
    transposed = csr_transpose(a)
    expected = a.T.tocsr()
    expected.sort_indices()
    assert transposed.shape == (900, 5000) and transposed.has_sorted_indices
    assert np.array_equal(transposed.indptr, expected.indptr)
    assert np.array_equal(transposed.indices, expected.indices)
    assert np.array_equal(transposed.data, expected.data)
    assert csr_transpose(sp.csr_matrix((0, 4))).shape == (4, 0)


def test_row_lengths_of_an_earlier_product_give_the_same_product():
    """The row lengths of a product of the same patterns, values aside: the same matrix,
    entry for entry; lengths of another product are refused."""
    rng = np.random.default_rng(7)
    j = sp.random(600, 90, density=0.04, random_state=4, format="csr")
    addend = sp.random(90, 90, density=0.05, random_state=5, format="csr")
    first = csr_product(j.T, j, add=addend, upper=True)
    # other values, the same patterns
    j.data = rng.normal(size=j.nnz)
    addend.data = rng.normal(size=addend.nnz)
    fresh = csr_product(j.T, j, add=addend, upper=True)
    reused = csr_product(j.T, j, add=addend, upper=True, row_lengths=np.diff(first.indptr))
    assert np.array_equal(reused.indptr, fresh.indptr)
    assert np.array_equal(reused.indices, fresh.indices)
    assert np.array_equal(reused.data, fresh.data)
    expected = sp.triu(j.T @ j + addend)
    assert abs(reused - expected).max() <= 1e-12 * abs(expected).max()
    other = sp.random(600, 90, density=0.04, random_state=6, format="csr")
    with pytest.raises(ValueError, match="row_lengths are not this product's"):
        csr_product(other.T, other, upper=True, row_lengths=np.diff(first.indptr))
    with pytest.raises(ValueError, match="row_lengths must have shape"):
        csr_product(j.T, j, row_lengths=np.ones(3, dtype=np.int64))
