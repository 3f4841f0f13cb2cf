"""Question (issue 50, speed): the conjugate gradients' products with the Hessian and the
product ``J^T J`` are scipy's single-threaded C++. Would compiled loops over the CSR arrays,
run on both cores (numba ``prange``), be faster on this 2-core machine?

Run from the repository root, after ``experiments/surfels_step_cost.py capture``::

    PYTHONPATH=src .venv/bin/python experiments/surfels_parallel_products.py

Answer (2-core Intel Xeon, nothing else running, 2026-12-06 at ee7dce6; the step-cost problem:
14 frames, 504 surfels, H 9.16 million entries): no. A product with H takes 7.99 ms in scipy
and 8.94 ms compiled on 2 threads (bit-identical); ``J^T J`` 0.21 s in scipy and 0.27 s
compiled (a row-parallel Gustavson product with a dense accumulator per thread, both passes).
Both are bound by memory bandwidth, which the two cores share; scipy stays.

Later (2026-12-07, a 2-core AMD EPYC compiled for ``znver4``, on crane's 8 + 8 merge): there
the row-parallel product gained 24.3 -> 18.1 ms, ``J^T J`` about twice, and the Hessian's
upper triangle alone (half the bytes) 8.8 ms; ``surfels`` uses all three
(``fourd.geometry.sparse_products``, ``experiments/surfels_sparse_algebra.py``).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import numba  # noqa: E402
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from surfels_matrix_free import best_of, step_system  # noqa: E402


@numba.njit(cache=True, parallel=True, nogil=True)
def csr_matvec(indptr, indices, data, x, out):
    for i in numba.prange(len(indptr) - 1):
        s = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            s += data[k] * x[indices[k]]
        out[i] = s

@numba.njit(cache=True, parallel=True, nogil=True)
def gram_count(tp, ti, jp, ji, n, chunks):
    # rows of H = J^T J: row i = sum over r in col i of J: J[r,:]
    counts = np.zeros(n, np.int64)
    for c in numba.prange(chunks):
        mark = np.full(n, -1, np.int64)
        for i in range(c * n // chunks, (c + 1) * n // chunks):
            cnt = 0
            for a in range(tp[i], tp[i + 1]):
                r = ti[a]
                for b in range(jp[r], jp[r + 1]):
                    j = ji[b]
                    if mark[j] != i:
                        mark[j] = i
                        cnt += 1
            counts[i] = cnt
    return counts

@numba.njit(cache=True, parallel=True, nogil=True)
def gram_fill(tp, ti, td, jp, ji, jd, n, chunks, hp, hi, hd):
    for c in numba.prange(chunks):
        acc = np.zeros(n)
        mark = np.full(n, -1, np.int64)
        for i in range(c * n // chunks, (c + 1) * n // chunks):
            start = hp[i]
            cnt = 0
            for a in range(tp[i], tp[i + 1]):
                r = ti[a]
                v = td[a]
                for b in range(jp[r], jp[r + 1]):
                    j = ji[b]
                    if mark[j] != i:
                        mark[j] = i
                        hi[start + cnt] = j
                        cnt += 1
                        acc[j] = v * jd[b]
                    else:
                        acc[j] += v * jd[b]
            for k in range(start, start + cnt):
                hd[k] = acc[hi[k]]

def gram(transposed, jacobian):
    """``J^T J`` from ``J`` and its transpose (both CSR), rows in chunks over the threads."""
    n, chunks = transposed.shape[0], 64
    counts = gram_count(
        transposed.indptr, transposed.indices, jacobian.indptr, jacobian.indices, n, chunks
    )
    hp = np.zeros(n + 1, np.int64)
    np.cumsum(counts, out=hp[1:])
    hi, hd = np.empty(hp[-1], np.int32), np.empty(hp[-1])
    gram_fill(
        transposed.indptr, transposed.indices, transposed.data,
        jacobian.indptr, jacobian.indices, jacobian.data, n, chunks, hp, hi, hd,
    )
    return sp.csr_matrix((hd, hi, hp), shape=(n, n))

def main() -> None:
    _, hessian, jacobian = step_system()
    print(f"{numba.get_num_threads()} threads; H {hessian.nnz} entries, J {jacobian.nnz}")
    p = np.random.default_rng(0).normal(size=hessian.shape[0])
    out = np.empty_like(p)
    csr_matvec(hessian.indptr, hessian.indices, hessian.data, p, out)
    print("compiled product equals scipy's bit for bit:", np.array_equal(out, hessian @ p))
    print(f"H p: scipy {1e3 * best_of(lambda: hessian @ p, 20):.2f} ms, compiled "
          f"{1e3 * best_of(lambda: csr_matvec(hessian.indptr, hessian.indices, hessian.data, p, out), 20):.2f} ms")
    transposed = jacobian.T.tocsr()
    gram(transposed, jacobian)
    print(f"J^T J: scipy {best_of(lambda: transposed @ jacobian, 3):.3f} s, compiled "
          f"{best_of(lambda: gram(transposed, jacobian), 3):.3f} s")


if __name__ == "__main__":
    main()
