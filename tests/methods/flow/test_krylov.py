"""The flow's in-place Krylov solvers against scipy's."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from flow_scenes import (
    _saddle_matrix,
)

from fourd.methods.flow.krylov import jacobi_cg, minres_inplace


def test_jacobi_cg_follows_scipys_cg():
    """The compiled Jacobi-preconditioned CG of the postprocessing: scipy's solution, residual
    within ``rtol``, as many steps as scipy's (give or take one), 0 steps from the answer, and
    ``info`` set when ``maxiter`` is too small."""
    from scipy.sparse.linalg import cg

    rng = np.random.default_rng(4)
    n = 30
    path = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    A = (sp.kron(path, sp.identity(n)) + sp.kron(sp.identity(n), path)).tocsr()
    A = (A + sp.diags(rng.uniform(0.01, 1.0, n * n))).tocsr()
    A.indices = A.indices.astype(np.int32)
    b = rng.normal(size=n * n)
    x0 = rng.normal(size=n * n)
    steps = []
    expected, info = cg(A, b, x0=x0, rtol=1e-8, maxiter=2000,
                        M=sp.diags(1.0 / A.diagonal()), callback=lambda _: steps.append(1))
    x, status, taken = jacobi_cg(A, b, x0, rtol=1e-8, maxiter=2000)
    assert info == 0 and status == 0
    assert np.linalg.norm(b - A @ x) <= 1e-8 * np.linalg.norm(b)
    assert abs(x - expected).max() < 1e-6 * abs(expected).max()
    assert abs(taken - len(steps)) <= 1
    exact = sp.linalg.spsolve(A.tocsc(), b)
    assert jacobi_cg(A, A @ exact, exact, rtol=1e-8, maxiter=10)[2] == 0
    assert jacobi_cg(A, b, x0, rtol=1e-8, maxiter=3)[1:] == (3, 3)


def test_minres_inplace_follows_scipys_minres():
    """The in-place MINRES takes scipy's steps: the same iterate after the first steps on a
    preconditioned symmetric indefinite system (later ones part by rounding as Lanczos
    loses orthogonality: 1e-14 after 10 steps, 4e-4 after 30 here), and it stops with a
    small residual where scipy's reports convergence."""
    from scipy.sparse.linalg import minres

    a = sp.random(60, 50, density=0.1, random_state=0, format="csr")
    A = (a.T @ a + sp.identity(50)).tocsr()
    B = sp.random(15, 50, density=0.2, random_state=2, format="csr")
    K = _saddle_matrix(A, B, 1e-3).tocsr()
    diagonal = np.concatenate([A.diagonal() + np.asarray(B.multiply(B).sum(axis=0)).ravel(),
                               np.ones(15)])
    b = np.random.default_rng(3).normal(size=65)
    x0 = np.random.default_rng(4).normal(size=65)
    for steps in (1, 5, 10):
        expected, _ = minres(K, b, x0=x0, rtol=1e-12, maxiter=steps,
                             M=sp.diags(1.0 / diagonal))
        x = x0.copy()
        taken = minres_inplace(lambda z, out: np.copyto(out, K @ z),
                               lambda r, out: np.divide(r, diagonal, out=out), b, x,
                               rtol=1e-12, maxiter=steps)
        assert taken == steps
        assert np.allclose(x, expected, rtol=0, atol=1e-9 * abs(expected).max())
    counted = []
    x = np.zeros(65)
    taken = minres_inplace(lambda z, out: np.copyto(out, K @ z),
                           lambda r, out: np.divide(r, diagonal, out=out), b, x, rtol=1e-8,
                           maxiter=500, callback=counted.append)
    _, info = minres(K, b, rtol=1e-8, maxiter=500, M=sp.diags(1.0 / diagonal))
    assert info == 0 and len(counted) == taken < 500
    assert np.linalg.norm(b - K @ x) <= 1e-6 * np.linalg.norm(b)
