"""Krylov solvers of the flow method, updating their vectors in place: a preconditioned
MINRES for the saddle system (:func:`minres_inplace`) and a Jacobi-preconditioned CG over
the cores for SPD systems (:func:`jacobi_cg`).
"""


from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.sparse_products import unsigned


def minres_inplace(apply_K, apply_M, b: np.ndarray, x: np.ndarray, *, rtol: float,
                   maxiter: int, callback=None) -> int:
    """Preconditioned MINRES (Paige and Saunders 1975) for ``K x = b``, ``K`` [N, N]
    symmetric, ``M`` symmetric positive definite, from ``x`` [N] (float64, updated in place).

    ``apply_K(z, out)`` and ``apply_M(r, out)`` write ``K z`` and ``M^-1 r`` into ``out``.
    The recurrence and the stopping tests are scipy's ``minres`` (``||r||_M / (||K|| ||x||)``
    or ``||K r|| / (||K|| ||r||)`` estimated below ``rtol``, ``x`` at machine precision, or
    ``maxiter`` steps), with eight vectors updated in place instead of new arrays every
    step: on squash-ball's first flow system at resolution 64 (10.2M unknowns) the solve's
    peak memory went 4.15 -> 3.98 GB, its iterates the same. Returns the number of steps
    taken."""
    eps = np.finfo(float).eps
    size = len(b)
    r1 = np.empty(size)
    apply_K(x, r1)
    np.subtract(b, r1, out=r1)
    y = np.empty(size)
    apply_M(r1, y)
    beta1 = float(r1 @ y)
    if beta1 < 0:
        raise ValueError("MINRES: the preconditioner is not positive definite")
    if beta1 == 0:
        return 0
    beta1 = np.sqrt(beta1)
    r2 = r1.copy()
    v, w, w1, w2 = np.empty(size), np.zeros(size), np.zeros(size), np.zeros(size)
    oldb, beta, dbar, epsln, phibar = 0.0, beta1, 0.0, 0.0, beta1
    cs, sn, tnorm2, gmax, gmin = -1.0, 0.0, 0.0, 0.0, np.finfo(float).max
    steps = 0
    while steps < maxiter:
        steps += 1
        np.multiply(y, 1.0 / beta, out=v)
        apply_K(v, y)  # y = K v (the preconditioned vector is no longer needed)
        if steps >= 2:
            _axpy(r1, y, -beta / oldb)
        alfa = float(v @ y)
        _axpy(r2, y, -alfa / beta)
        r1, r2, y = r2, y, r1  # the oldest residual's buffer takes M^-1 r2
        apply_M(r2, y)
        oldb, beta = beta, float(r2 @ y)
        if beta < 0:
            raise ValueError("MINRES: the preconditioner is not positive definite")
        beta = np.sqrt(beta)
        tnorm2 += alfa**2 + oldb**2 + beta**2
        exhausted = steps == 1 and beta / beta1 <= 10 * eps
        # the previous plane rotation, then the next one
        oldeps = epsln
        delta = cs * dbar + sn * alfa
        gbar = sn * dbar - cs * alfa
        epsln = sn * beta
        dbar = -cs * beta
        root = np.hypot(gbar, dbar)
        gamma = max(np.hypot(gbar, beta), eps)
        cs, sn = gbar / gamma, beta / gamma
        phi, phibar = cs * phibar, sn * phibar
        w1, w2, w = w2, w, w1  # w = (v - oldeps w1 - delta w2) / gamma in the oldest's buffer
        np.multiply(v, 1.0 / gamma, out=w)
        _axpy(w1, w, -oldeps / gamma)
        _axpy(w2, w, -delta / gamma)
        _axpy(w, x, phi)
        gmax, gmin = max(gmax, gamma), min(gmin, gamma)
        if callback is not None:
            callback(x)
        anorm = np.sqrt(tnorm2)
        xnorm = float(np.linalg.norm(x))
        test1 = np.inf if xnorm == 0 or anorm == 0 else phibar / (anorm * xnorm)
        test2 = np.inf if anorm == 0 else root / anorm
        if (
            exhausted
            or test1 <= rtol
            or test2 <= rtol
            or 1 + test1 <= 1
            or 1 + test2 <= 1
            or gmax / gmin >= 0.1 / eps
            or anorm * xnorm * eps >= beta1
        ):
            break
    return steps


@numba.njit(cache=True)
def _axpy(source: np.ndarray, target: np.ndarray, factor: float) -> None:
    """``target += factor * source`` in place, without a temporary. Not BLAS's ``daxpy``:
    OpenBLAS's threads keep spinning after it returns and slowed the single-threaded
    smoother that follows (crane at resolution 32, first solve: 6.1 s against 4.1 s with
    scipy's MINRES)."""
    for i in range(len(target)):
        target[i] += factor * source[i]


#: Chunks of :func:`jacobi_cg`'s rows: its dot products are summed chunk by chunk in a fixed
#: order, so that the iterates do not depend on the number of cores.
CG_CHUNKS = 64


@numba.njit(cache=True, parallel=True)
def _cg_pass(indptr, indices, data, inverse, b, x, r, z, p, q, bounds, step, out):
    """One pass of :func:`jacobi_cg` over the row chunks ``bounds``, per chunk partial
    sums into ``out`` [chunks, 2]. ``step`` 0: ``r = b - A x``, ``z = r / diag`` (sums
    ``r.r``, ``r.z``); 1: ``q = A p`` (sum ``p.q``); 2: ``x += a p``, ``r -= a q``,
    ``z = r / diag`` with ``a = out[0, 0]`` on entry (sums ``r.r``, ``r.z``)."""
    alpha = out[0, 0]
    for c in numba.prange(len(bounds) - 1):
        first = 0.0
        second = 0.0
        for i in range(bounds[c], bounds[c + 1]):
            if step == 1:
                total = 0.0
                for k in range(indptr[i], indptr[i + 1]):
                    total += data[k] * p[indices[k]]
                q[i] = total
                first += p[i] * total
            else:
                if step == 0:
                    total = 0.0
                    for k in range(indptr[i], indptr[i + 1]):
                        total += data[k] * x[indices[k]]
                    r[i] = b[i] - total
                else:
                    x[i] += alpha * p[i]
                    r[i] -= alpha * q[i]
                z[i] = inverse[i] * r[i]
                first += r[i] * r[i]
                second += r[i] * z[i]
        out[c, 0] = first
        out[c, 1] = second


@numba.njit(cache=True, parallel=True)
def _update_direction(z, p, beta):
    """``p = z + beta p`` in place, on all cores."""
    for i in numba.prange(len(p)):
        p[i] = z[i] + beta * p[i]


def jacobi_cg(
    A: sp.csr_matrix, b: np.ndarray, x0: np.ndarray, *, rtol: float, maxiter: int
) -> tuple[np.ndarray, int, int]:
    """Conjugate gradients for the symmetric positive definite CSR ``A`` [n, n] and ``b``
    [n] from ``x0``, preconditioned by ``A``'s diagonal, until ``|b - A x| <= rtol |b|`` (as
    scipy's ``cg`` with ``atol`` 0). Returns ``x`` [n], ``info`` (0: converged, else
    ``maxiter``) and the steps taken.

    Why not scipy's ``cg``: its products and vector updates run on one core with a Python
    step each; here each step is three passes over the rows, on all cores (the flow's
    postprocessing Laplace system of squash-ball at resolution 64, 6.7M rows, 35 steps:
    3.5 s in scipy's, 1.5 s here; see :func:`fourd.methods.flow.post.implicit_function`). The sums go
    chunk by chunk (:data:`CG_CHUNKS`), so the result does not depend on the number of cores.
    """
    n = A.shape[0]
    indptr, indices = unsigned(A.indptr), unsigned(A.indices)
    data = np.asarray(A.data, dtype=np.float64)
    inverse = 1.0 / A.diagonal()
    b = np.ascontiguousarray(b, dtype=np.float64)
    x = np.array(x0, dtype=np.float64, copy=True)
    r, z, p, q = (np.empty(n) for _ in range(4))
    bounds = np.linspace(0, n, CG_CHUNKS + 1).astype(np.int64)
    sums = np.zeros((CG_CHUNKS, 2))
    target = rtol * float(np.linalg.norm(b))
    _cg_pass(indptr, indices, data, inverse, b, x, r, z, p, q, bounds, 0, sums)
    rr, rz = sums.sum(axis=0)
    previous = 0.0
    for step in range(maxiter):
        if np.sqrt(rr) <= target:
            return x, 0, step
        if step == 0:
            p[:] = z
        else:
            _update_direction(z, p, rz / previous)
        _cg_pass(indptr, indices, data, inverse, b, x, r, z, p, q, bounds, 1, sums)
        pq = sums[:, 0].sum()
        previous = rz
        sums[0, 0] = rz / pq
        _cg_pass(indptr, indices, data, inverse, b, x, r, z, p, q, bounds, 2, sums)
        rr, rz = sums.sum(axis=0)
    return x, (0 if np.sqrt(rr) <= target else maxiter), maxiter
