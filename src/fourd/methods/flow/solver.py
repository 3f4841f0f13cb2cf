"""MINRES with the block-diagonal preconditioner of paper 002, section 5.

The system ``K z = b`` with ``K = [[A, B^T], [B, -eps I]]`` is symmetric indefinite. It is
solved by MINRES preconditioned with ``M = diag(A + B^T B / gamma, gamma I)`` (Greif and
Schoetzau 2006): the preconditioned matrix has the eigenvalue 1 with multiplicity ``dim A``
and its negative eigenvalues in ``(-1, 0)``, clustered near -1, so MINRES converges in far
fewer iterations than the system's size. Applying ``M^-1`` needs solves with the SPD
``A + B^T B / gamma`` (the inner iteration): conjugate gradients preconditioned by
classical Ruge-Stueben AMG (``inner="cg-amg"``; smoothed aggregation measured
worse on ``A + B^T B``) or by an incomplete factorisation with drop
tolerance 0.01 (``inner="cg-ilu"``, the paper's choice; scipy has no incomplete Cholesky,
so its ILU stands in), to ``inner_rtol`` (1e-6 in the paper). ``inner="amg"`` replaces the
inner CG by one symmetric AMG V-cycle, a fixed SPD approximation of the inverse (cheaper
per step, more outer iterations); its hierarchy can keep only the largest entries of
each interpolation row (``interpolation_entries``: sparser coarse matrices, cheaper steps).

Measured (small test system, 7.9k unknowns): ``cg-amg`` 7 MINRES iterations, residual 2e-6,
10 s; ``cg-ilu`` did not finish in 5 minutes (scipy's ``spilu`` set-up is slow on this
matrix). On full problems the exact inner solve needs 100-200 CG steps per MINRES step, so
the method's default is ``amg`` with a capped number of MINRES steps per IRLS iteration,
warm-started from the previous iterate (an inexact solve, see the method's report).

``eps`` (``softness``) is 0 in the paper. Clamping and noisy data make the constraints
inconsistent at times (the paper's Discussion: "they are satisfied in a least squares
sense"); a small ``eps`` makes that explicit and keeps ``K`` non-singular.

Nothing here forms a dense matrix or factorises ``K``; MINRES applies ``K`` through ``A`` and
``B`` (:func:`_saddle_apply`) without assembling it, in a MINRES that updates its vectors in
place (:func:`minres_inplace`). ``A + B^T B / gamma`` is formed (in single precision) only for
the AMG set-up: the V-cycle's finest level then sweeps it through ``A`` and ``B^T``
(:class:`NormalFinest`, 5 nonzeros per row against 15) and it is freed. Squash-ball's first
flow system at resolution 64 (7.9M unknowns, 8 MINRES steps): the solve's peak 3.98 ->
3.37 GB, the same residual. The V-cycle costs 5-7% more (captured crane system at 64,
medians of 9 interleaved: 218 -> 232 ms; the sweeps read ``A``'s double-precision entries
and ``B^T``'s column indices, then ``B^T x`` is formed again after the coarse correction).
"""

from __future__ import annotations

import ctypes
import logging
import time
from typing import Literal, NamedTuple

import numba
import numpy as np
import pyamg
import scipy.sparse as sp
from pyamg import amg_core
from pyamg.multilevel import MultilevelSolver
from pyamg.relaxation.smoothing import change_smoothers
from scipy.sparse.linalg import LinearOperator, cg, spilu

from fourd.methods.flow import sweeps
from fourd.methods.flow.sparse import (
    csr_product,
    drop_weak_entries,
    galerkin_product,
    principal_submatrix,
    strong_pattern,
    strong_values,
    submatrix,
    transpose_pattern,
    truncate_rows,
    unsigned,
    used_columns,
)

log = logging.getLogger("fourd.methods.flow.solver")

Inner = Literal["cg-amg", "cg-ilu", "amg"]


class SaddleSolution(NamedTuple):
    """Result of :func:`solve_saddle`.

    u : [n] primal unknowns; multipliers : [m].
    iterations : outer MINRES iterations; inner_iterations : total inner CG iterations.
    residual : true relative residual ``||b - K z|| / ||b||``.
    converged : MINRES reported convergence (``info == 0``).
    seconds : wall time of setup + solve.
    interpolations : the interpolation operators of the inner V-cycle's AMG hierarchy, finest
        first (``inner="amg"``; else None), for :func:`solve_saddle`'s ``reuse`` later.
    coarse_matrices : that hierarchy's coarse matrices, the first coarse level's first and
        the coarsest last (``inner="amg"`` with more than one level; else None), for
        :func:`solve_saddle`'s ``reuse_coarse`` later.
    """

    u: np.ndarray
    multipliers: np.ndarray
    iterations: int
    inner_iterations: int
    residual: float
    converged: bool
    seconds: float
    interpolations: tuple | None = None
    coarse_matrices: tuple | None = None


# Direct interpolation instead of pyamg's default classical one: on a captured crane system at
# resolution 64 (1.7M unknowns) the set-up takes 8.4 s instead of 13.5 s and 60 MINRES steps
# reach a relative residual of 2.5e-2 instead of 2.6e-2, at the same cost per step.
_AMG_SETUP = {"max_coarse": 500, "interpolation": "direct"}

# Symmetric Gauss-Seidel (a forward and a backward sweep) before and after the coarse
# correction on the finest level, one forward sweep before and one backward after on the
# coarser ones: each level's post-smoother is its pre-smoother's adjoint, so the V-cycle stays
# symmetric. The coarse levels are dense (about 80 nonzeros per row on the first, against 16
# on the finest), and halving their sweeps left the residual where it was: 40 MINRES steps on
# captured resolution-64 systems, symmetric everywhere against this, crane 18.1 -> 14.0-15.3
# s with residual 3.74e-2 -> 3.75e-2, dfaust-hopping 21.6 -> 20.2 s with 9.46e-3 -> 9.53e-3
# (forward / backward on the finest level too: 1.56e-2).
_SYMMETRIC = ("gauss_seidel", {"sweep": "symmetric"})
_PRESMOOTHERS = [_SYMMETRIC, ("gauss_seidel", {"sweep": "forward"})]
_POSTSMOOTHERS = [_SYMMETRIC, ("gauss_seidel", {"sweep": "backward"})]


def _load_malloc_trim():
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc
        return None


_MALLOC_TRIM = _load_malloc_trim()


def release_free_heap() -> None:
    """Give the C heap's freed pages back to the system (glibc's ``malloc_trim``; nothing
    elsewhere). Arrays under glibc's mmap threshold (up to 32 MiB) live on the heap, and the
    holes they leave stay resident: squash-ball at resolution 64 peaked 0.3 GiB higher in its
    second IRLS iteration's AMG set-up than in its first, with the same arrays alive."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


def _saddle_apply(A, B, BT, softness: float, z: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out = [[A, B^T], [B, -softness I]] z`` (``A`` [n, n], ``B`` [m, n], ``BT`` its
    transpose, e.g. the view ``B.T``); returns ``out``. Never assembled: a third copy of
    ``A`` and ``B`` (squash-ball at resolution 64, 7.9 million unknowns and 2.3 million
    constraints: peak memory 6.48 -> 5.79 GB at a00735a). CSR ``A``, ``B`` and ``BT`` are
    applied on all cores (:func:`.sweeps.multiply_add`)."""
    n = A.shape[0]
    u, multipliers = z[:n], z[n:]
    top, bottom = out[:n], out[n:]
    top.fill(0)
    bottom.fill(0)
    for matrix, vector, into in ((A, u, top), (BT, multipliers, top), (B, u, bottom)):
        if sp.issparse(matrix) and matrix.format == "csr":
            sweeps.multiply_add(matrix, vector, into)
        else:
            into += matrix @ vector
    if softness:
        bottom -= softness * multipliers
    return out


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


def _multilevel(levels: list, A: sp.csr_matrix) -> MultilevelSolver:
    """The solver of ``levels`` (with ``A``, ``P``, ``R``) and the coarsest matrix ``A``."""
    coarsest = MultilevelSolver.Level()
    coarsest.A = A
    ml = MultilevelSolver([*levels, coarsest], coarse_solver="pinv")
    change_smoothers(ml, list(_PRESMOOTHERS), list(_POSTSMOOTHERS))
    return ml


def _level(A: sp.csr_matrix, P: sp.csr_matrix, coarse_drop: float = 0.0):
    """One level of a hierarchy and the next coarser matrix, the Galerkin product ``P^T A P``
    (on all cores, without ``A P``: :func:`.sparse.galerkin_product`), its weak entries
    lumped onto its diagonal if ``coarse_drop`` > 0 (:func:`.sparse.drop_weak_entries`)."""
    level = MultilevelSolver.Level()
    # the restriction is P's transpose as a view, not a second copy of P
    level.A, level.P, level.R = A, P, P.T
    coarse = galerkin_product(P.T.tocsr(), A, P)
    if coarse_drop > 0:
        coarse = drop_weak_entries(coarse, coarse_drop)
    return level, coarse


def _direct_interpolation(A: sp.csr_matrix, theta: float) -> sp.csr_matrix | None:
    """Ruge-Stueben splitting and direct interpolation [n, coarse] of ``A`` [n, n] (None if
    every or no point would be coarse): what pyamg's ``classical_strength_of_connection``,
    ``RS`` and ``direct_interpolation`` compute, through its kernels, with the strong
    connections' pattern and its transpose (:func:`.sparse.strong_pattern`,
    :func:`.sparse.transpose_pattern`), then the pattern's values
    (:func:`.sparse.strong_values`), instead of four full copies of ``A`` with values. Squash-ball's first flow system at resolution 64
    (7.9M unknowns, 121M nonzeros, float32; with the saddle system and its right side
    loaded): the hierarchy's set-up peaked at 5.1 GB with pyamg's functions, at 3.2 GB
    with these, no more than the finished hierarchy holds (and in 31 s instead of 36)."""
    n = A.shape[0]
    index = np.int32
    if A.nnz >= np.iinfo(index).max:
        raise ValueError(f"{A.nnz} nonzeros: beyond the AMG kernels' 32-bit indices")
    A = sp.csr_matrix(
        (A.data, A.indices.astype(index, copy=False), A.indptr.astype(index, copy=False)),
        shape=A.shape,
    )
    # the splitting takes the pattern and its transpose, the interpolation the pattern with
    # A's values: never all three at once
    strong_indptr, strong_indices = strong_pattern(A, theta)
    transposed_indptr, transposed_indices = transpose_pattern(strong_indptr, strong_indices, n)
    splitting = np.empty(n, index)
    amg_core.rs_cf_splitting(
        n,
        strong_indptr,
        strong_indices,
        transposed_indptr,
        transposed_indices,
        np.zeros(n, index),
        splitting,
    )
    del transposed_indptr, transposed_indices
    coarse = int(splitting.sum())
    if coarse == 0 or coarse == n:
        return None
    strong_data = strong_values(A, theta, strong_indptr, strong_indices)
    indptr = np.empty(n + 1, index)
    amg_core.rs_direct_interpolation_pass1(n, strong_indptr, strong_indices, splitting, indptr)
    indices = np.empty(indptr[-1], index)
    data = np.empty(indptr[-1], A.dtype)
    amg_core.rs_direct_interpolation_pass2(
        n, A.indptr, A.indices, A.data, strong_indptr, strong_indices, strong_data,
        splitting, indptr, indices, data,
    )
    return sp.csr_matrix((data, indices, indptr), shape=(n, coarse))


def amg_hierarchy(
    S: sp.csr_matrix,
    *,
    max_coarse: int = 500,
    max_levels: int = 10,
    interpolation_entries: int | None = None,
    coarse_drop: float = 0.0,
):
    """The Ruge-Stueben AMG hierarchy of ``S`` [n, n] (SPD) for the V-cycle of ``inner="amg"``.

    What ``pyamg.ruge_stuben_solver(S, max_coarse=500, interpolation="direct")`` builds
    (classical strength of connection with threshold 0.25, RS splitting, direct
    interpolation), in less memory (:func:`_direct_interpolation`) and with the Galerkin
    products on all cores: on a captured dfaust-hopping system at resolution 64 (2.1M
    unknowns, 2 cores) the first level's product takes 2.0 s instead of 4.3 s. The entries
    agree to single-precision rounding (summation order).

    A higher strength threshold made the set-up cheaper at the same residual but not the
    output: on the captured first squash-ball system at resolution 64 (40 MINRES steps) 0.25
    took 55 s to a residual of 1.71e-2, 0.5 51 s to 1.76e-2, 0.7 44 s to 1.74e-2; but with
    0.7 squash-ball at 64 came out at Chamfer / completeness-95 0.0046 / 0.0089 against
    0.0040 / 0.0077 (``exp`` runs, 20k samples) and its later solves were no faster. A V(1,1)
    cycle (one forward sweep before, one backward after, on the finest level) instead of two
    of each halved the finest level's sweeps but left the residual at 3.3e-2 after 40 steps
    (48.8 s).

    ``interpolation_entries``: keep only this many largest entries of each row of every
    interpolation (:func:`.sparse.truncate_rows`; None: all, pyamg's hierarchy).
    ``coarse_drop``: drop the weak entries of every coarse matrix, lumped onto its diagonal
    (:func:`.sparse.drop_weak_entries`; 0: none, Galerkin coarse matrices).
    Smoothers: :data:`_PRESMOOTHERS` / :data:`_POSTSMOOTHERS`."""
    levels = []
    A = sp.csr_matrix(S)
    while len(levels) + 1 < max_levels and A.shape[0] > max_coarse:
        P = _direct_interpolation(A, theta=0.25)
        if P is None:
            break
        if interpolation_entries is not None:
            P = truncate_rows(P, interpolation_entries)
        level, A = _level(A, P, coarse_drop)
        levels.append(level)
    return _multilevel(levels, A)


def restrict_interpolations(
    interpolations: tuple | list,
    rows: np.ndarray,
    coarse_matrices: tuple | list | None = None,
    *,
    consume: bool = False,
) -> tuple:
    """An earlier hierarchy's interpolation operators (finest first) restricted to a subset
    of its finest unknowns, for :func:`restricted_hierarchy`.

    ``rows`` [n]: the index of each new unknown among the earlier finest level's. Each level
    keeps those rows and the coarse columns they still use, which are the next level's rows;
    the chain stops at a level with no column left.

    With ``coarse_matrices`` (the earlier hierarchy's, :attr:`SaddleSolution.coarse_matrices`)
    returns ``(interpolations, coarse matrices)``, each coarse matrix restricted to the rows
    and columns its level keeps (principal submatrices: still symmetric positive definite),
    for :func:`solve_saddle`'s ``reuse_coarse``.

    With ``consume`` (``interpolations`` and ``coarse_matrices`` given as lists), each earlier
    matrix is dropped from its list once restricted, so that a caller holding no other
    reference frees it before the next level is restricted (squash-ball at resolution 64:
    the first coarse matrix is 0.65 GiB, and the whole earlier hierarchy 1.25 GiB)."""
    restricted, coarse = [], []
    for level in range(len(interpolations)):
        P = interpolations[level]
        used = used_columns(P, rows)
        if len(used) == 0:  # nothing left to interpolate from
            break
        restricted.append(submatrix(P, rows, used))
        del P
        if consume:
            interpolations[level] = None
        if coarse_matrices is not None:
            coarse.append(
                principal_submatrix(coarse_matrices[level], used, overwrite=consume)
            )
            if consume:
                coarse_matrices[level] = None
        rows = used
    if coarse_matrices is None:
        return tuple(restricted)
    return tuple(restricted), tuple(coarse)


def frozen_hierarchy(interpolations: tuple, coarse_matrices: tuple) -> MultilevelSolver:
    """An AMG hierarchy from given interpolation operators and coarse matrices (finest first,
    as :func:`restrict_interpolations` returns them with ``coarse_matrices``) without a
    finest matrix: for :func:`v_cycle` with ``finest``. The V-cycle is symmetric positive
    definite as long as every coarse matrix is, whether or not it is the Galerkin product
    of the finest matrix in use."""
    levels = []
    for P in interpolations:
        level = MultilevelSolver.Level()
        level.A, level.P, level.R = None, P, P.T
        levels.append(level)
    for level, A in zip(levels[1:], coarse_matrices[:-1], strict=True):
        level.A = A
    return _multilevel(levels, coarse_matrices[-1])


def restricted_hierarchy(
    S: sp.csr_matrix, interpolations: tuple, coarse_drop: float = 0.0
) -> MultilevelSolver:
    """An AMG hierarchy for ``S`` [n, n] from given interpolation operators (finest first,
    the first with ``n`` rows, each next one's rows the previous one's columns: e.g.
    :func:`restrict_interpolations` of an earlier hierarchy's).

    The coarse matrices are the Galerkin products ``P^T A P`` with ``S`` (so the V-cycle
    stays a symmetric positive definite preconditioner). Skips the strength, splitting and
    interpolation set-up of every level. ``coarse_drop`` as in :func:`amg_hierarchy`."""
    levels = []
    A = S
    for P in interpolations:
        level, A = _level(A, P, coarse_drop)
        levels.append(level)
    return _multilevel(levels, A)


class NormalFinest(NamedTuple):
    """The finest matrix ``S = A + C C^T`` [n, n] of a hierarchy without ``S``: ``A`` [n, n]
    CSR, ``C`` [n, m] CSR (``B^T / sqrt(gamma)`` for the flow systems), ``diagonal`` [n] of
    ``S``. ``A`` and ``C`` hold 5 nonzeros per row on the flow systems, ``S`` 15."""

    A: sp.csr_matrix
    C: sp.csr_matrix
    diagonal: np.ndarray
    order: sweeps.Schedule | None = None
    CT: sp.csr_matrix | None = None


def normal_finest(
    A: sp.spmatrix, C: sp.spmatrix, groups: np.ndarray | None = None, CT: sp.spmatrix | None = None
) -> NormalFinest:
    """:class:`NormalFinest` of ``A + C C^T`` (``A`` [n, n], ``C`` [n, m]); with ``groups``
    (the time slice of every unknown) its sweeps run in parallel where the slices allow
    (:mod:`.sweeps`); ``CT``, the transpose of ``C`` as CSR, if at hand (for ``C^T x`` on all
    cores)."""
    A, C = sp.csr_matrix(A), sp.csr_matrix(C)
    diagonal = A.diagonal() + np.asarray(C.multiply(C).sum(axis=1)).ravel()
    order = None
    if groups is not None:
        order = sweeps.schedule(groups, sweeps.normal_reach(A, C, groups))
    return NormalFinest(A, C, diagonal, order, None if CT is None else sp.csr_matrix(CT))


@numba.njit(cache=True)
def _normal_sweep(a_indptr, a_indices, a_data, c_indptr, c_indices, c_data, diagonal, x, y,
                  rhs, first, stop, step):
    """One Gauss-Seidel sweep over rows ``first, first + step, ..`` (before ``stop``) of
    ``(A + C C^T) x = rhs``, with ``y = C^T x`` [m] kept up to date: row ``i`` of ``S x`` is
    ``A_i x + C_i y``, so every update is exactly Gauss-Seidel's on ``S``."""
    for i in range(first, stop, step):
        sweeps.normal_row(a_indptr, a_indices, a_data, c_indptr, c_indices, c_data, diagonal,
                          x, y, rhs, i)


@numba.njit(cache=True, parallel=True)
def _normal_residual(a_indptr, a_indices, a_data, c_indptr, c_indices, c_data, x, y, rhs, out):
    """``out = rhs - A x - C y`` (``y = C^T x``: the residual of ``(A + C C^T) x = rhs``)."""
    for i in numba.prange(len(rhs)):
        total = rhs[i]
        for p in range(a_indptr[i], a_indptr[i + 1]):
            total -= a_data[p] * x[a_indices[p]]
        for p in range(c_indptr[i], c_indptr[i + 1]):
            total -= c_data[p] * y[c_indices[p]]
        out[i] = total


def _symmetric_sweeps(finest: NormalFinest, x: np.ndarray, y: np.ndarray, rhs: np.ndarray):
    A, C = finest.A, finest.C
    if finest.order is not None:
        for forward in (True, False):
            sweeps.normal_sweep(A, C, finest.diagonal, x, y, rhs, finest.order, forward=forward)
        return
    arrays = (unsigned(A.indptr), unsigned(A.indices), A.data, unsigned(C.indptr),
              unsigned(C.indices), C.data, finest.diagonal, x, y, rhs)
    n = len(rhs)
    _normal_sweep(*arrays, 0, n, 1)
    _normal_sweep(*arrays, n - 1, -1, -1)


def v_cycle(
    ml: MultilevelSolver,
    b: np.ndarray,
    finest: NormalFinest | None = None,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """One V-cycle of ``ml`` from zero for ``A x = b`` [n] (``A`` its finest matrix), into
    ``out`` [n] when given (``b``'s dtype; returned).

    What ``ml.aspreconditioner(cycle="V").matvec(b)`` returns, without the two residual norms
    on the finest level that pyamg's ``solve`` computes around the cycle for its stopping
    test (two products with the finest matrix, 15% of the cycle on the captured systems).

    ``finest``: the finest matrix as ``A + C C^T`` (:class:`NormalFinest`), which the finest
    level's symmetric Gauss-Seidel sweeps and residual then use in ``b``'s precision instead
    of ``ml``'s finest matrix (which may then be None); the coarser levels take the
    restricted residual in their matrices' precision.

    The work arrays of every level are kept on ``ml`` from one cycle to the next
    (:func:`_work`)."""
    if len(ml.levels) == 1 or finest is None:
        # _cycle's result is a work array of ml's, reused by the next cycle
        x = ml.coarse_solver(ml.levels[0].A, b) if len(ml.levels) == 1 else _cycle(ml, 0, b)
        if out is None:
            return x.copy()
        out[:] = x
        return out
    level, C = ml.levels[0], finest.C
    x = np.zeros_like(b) if out is None else out
    x.fill(0)
    y = _work(ml, 0, "y", C.shape[1], b.dtype)
    _symmetric_sweeps(finest, x, y, b)
    coarse_dtype = ml.levels[1].A.dtype
    residual = _work(ml, 0, "residual", len(b), coarse_dtype, zero=False)
    A = finest.A
    _normal_residual(unsigned(A.indptr), unsigned(A.indices), A.data, unsigned(C.indptr),
                     unsigned(C.indices), C.data, x, y, b, residual)
    coarse_rhs = _restrict(ml, 0, residual)
    if len(ml.levels) == 2:
        coarse_x = ml.coarse_solver(ml.levels[-1].A, coarse_rhs)
    else:
        coarse_x = _cycle(ml, 1, coarse_rhs)
    sweeps.multiply_add(level.P, coarse_x, x)
    if finest.CT is None:
        y[:] = C.T @ x
    else:
        y.fill(0)
        sweeps.multiply_add(finest.CT, x, y)
    _symmetric_sweeps(finest, x, y, b)
    return x


def _work(ml: MultilevelSolver, depth: int, name: str, size, dtype, *, zero: bool = True):
    """The work array ``name`` [size] (an int or a shape) of level ``depth`` of ``ml``,
    zeroed (``zero``), kept on ``ml`` for the next cycle instead of allocated anew in each.
    Page faults of fresh arrays were suspected of the gap between a finest-level parallel
    sweep in the solve (about 13 ms on the captured crane system at resolution 64) and the
    same sweep alone (8.6 ms), but keeping the arrays did not close it: the gap is not
    explained."""
    work = ml.__dict__.setdefault("fourd_work", {})
    key = (depth, name)
    array = work.get(key)
    shape = (size,) if np.isscalar(size) else tuple(size)
    if array is None or array.shape != shape or array.dtype != dtype:
        array = np.empty(shape, dtype)
        work[key] = array
    if zero:
        array.fill(0)
    return array


def _restrict(ml: MultilevelSolver, depth: int, residual: np.ndarray) -> np.ndarray:
    """``R r`` of level ``depth`` (``R = P^T``) on all cores (:func:`.sweeps.transpose_multiply`)."""
    P = ml.levels[depth].P
    shape = (sweeps.TRANSPOSE_CHUNKS, P.shape[1])
    partial = _work(ml, depth, "restriction", shape, np.result_type(P.dtype, residual.dtype),
                    zero=False)
    return sweeps.transpose_multiply(P, residual, partial)


def _cycle(ml: MultilevelSolver, depth: int, rhs: np.ndarray) -> np.ndarray:
    # a module-level function, not a closure: a recursive closure is a reference cycle that
    # kept every solve's hierarchy alive until the garbage collector ran (0.9 GB per run of
    # crane at resolution 64)
    level = ml.levels[depth]
    x = _work(ml, depth, "x", len(rhs), rhs.dtype)
    level.presmoother(level.A, x, rhs)
    residual = _work(ml, depth, "residual", len(rhs), rhs.dtype, zero=False)
    residual[:] = rhs
    sweeps.multiply_add(level.A, x, residual, -1.0)
    coarse_rhs = _restrict(ml, depth, residual)
    if depth == len(ml.levels) - 2:
        coarse_x = ml.coarse_solver(ml.levels[-1].A, coarse_rhs)
    else:
        coarse_x = _cycle(ml, depth + 1, coarse_rhs)
    sweeps.multiply_add(level.P, coarse_x, x)
    level.postsmoother(level.A, x, rhs)
    return x


class _OrderedSweep:
    """A coarse level's smoother: one Gauss-Seidel sweep in a :class:`.sweeps.Schedule`'s
    row order (``forward``) or its reverse, in parallel; called as pyamg's smoothers are."""

    def __init__(self, order: sweeps.Schedule, forward: bool):
        self.order, self.forward = order, forward

    def __call__(self, A, x, b):
        sweeps.csr_sweep(A, x, b, self.order, forward=self.forward)


def parallel_smoothers(ml: MultilevelSolver, groups: np.ndarray) -> None:
    """Give the coarse levels of ``ml`` (whose finest unknowns lie in time slices ``groups``)
    Gauss-Seidel sweeps that run in parallel (:mod:`.sweeps`): the same forward sweep before
    and backward sweep after the coarse correction, in a row order that colours blocks of
    slices; a level whose entries reach too far across the slices keeps pyamg's sweeps."""
    for depth in range(1, len(ml.levels) - 1):
        groups = sweeps.coarse_groups(ml.levels[depth - 1].P, groups)
        level = ml.levels[depth]
        order = sweeps.schedule(groups, sweeps.csr_reach(level.A, groups))
        if order is not None:
            level.presmoother = _OrderedSweep(order, True)
            level.postsmoother = _OrderedSweep(order, False)


def _inner_operator(
    S: sp.csr_matrix,
    inner: Inner,
    inner_rtol: float,
    counter: list[int],
    inner_maxiter: int,
):
    """``r -> S^-1 r`` by preconditioned CG (``inner`` "cg-amg" or "cg-ilu")."""
    n = S.shape[0]
    if inner == "cg-amg":
        ml = pyamg.ruge_stuben_solver(S, **_AMG_SETUP)
        precond = ml.aspreconditioner(cycle="V")
    elif inner == "cg-ilu":
        ilu = spilu(S.tocsc(), drop_tol=0.01, fill_factor=4)
        precond = LinearOperator((n, n), matvec=ilu.solve)
    else:
        raise ValueError(f"unknown inner solver {inner!r}")

    def apply(r):
        def tick(_):
            counter[0] += 1

        norm = np.linalg.norm(r)
        if norm == 0:
            return np.zeros_like(r)
        z, _ = cg(S, r, rtol=inner_rtol, maxiter=inner_maxiter, M=precond, callback=tick)
        return z

    return apply


def solve_saddle(
    A: sp.spmatrix,
    B: sp.spmatrix,
    f: np.ndarray,
    g: np.ndarray,
    *,
    gamma: float = 1.0,
    softness: float = 0.0,
    rtol: float = 1e-4,
    inner: Inner = "cg-amg",
    inner_rtol: float = 1e-6,
    maxiter: int = 300,
    inner_maxiter: int = 200,
    x0: np.ndarray | None = None,
    reuse: tuple | None = None,
    reuse_coarse: tuple | None = None,
    interpolation_entries: int | None = None,
    coarse_drop: float = 0.0,
    overwrite_x0: bool = False,
    groups: np.ndarray | None = None,
) -> SaddleSolution:
    """Solve ``[[A, B^T], [B, -softness I]] [u; lambda] = [f; g]`` by preconditioned MINRES.

    Parameters
    ----------
    A : sparse [n, n], symmetric positive (semi-)definite.
    B : sparse [m, n].
    gamma : float
        Preconditioner parameter (1 in the paper).
    rtol : float
        Outer tolerance (the paper uses 1e-3 to 1e-5).
    x0 : ndarray [n + m], optional
        Starting guess (e.g. the previous IRLS iterate).
    reuse : tuple of sparse matrices, optional
        With ``inner="amg"``: interpolation operators for ``A + B^T B`` (finest first, the
        first with ``n`` rows), e.g. an earlier solve's :attr:`SaddleSolution.interpolations`
        restricted to this system's unknowns by :func:`restrict_interpolations`; the V-cycle
        then keeps them (:func:`restricted_hierarchy`) instead of a new set-up.
        Measured on the captured crane systems at resolution 64 (IRLS iterations 1 and 2
        from iteration 0's hierarchy): set-up 8.5-9.0 -> 4.1 s and 7.6 -> 3.7 s, residual
        after 40 steps 3.79e-2 -> 3.76e-2 and 3.94e-2 -> 3.92e-2.
    reuse_coarse : tuple of sparse matrices, optional
        With ``reuse``: the coarse matrices to go with it (an earlier solve's
        :attr:`SaddleSolution.coarse_matrices`, restricted by
        :func:`restrict_interpolations`). The V-cycle then keeps them too
        (:func:`frozen_hierarchy`) and ``A + B^T B`` is never formed: only the finest
        level's sweeps see this system, the coarse correction is the earlier system's. Still
        a symmetric positive definite preconditioner, a weaker one the more the systems
        differ; the set-up is a few restrictions instead of the Galerkin products.
    interpolation_entries : int, optional
        With ``inner="amg"``: keep only this many largest entries per row of every AMG
        interpolation (:func:`amg_hierarchy`; None: all). Measured on the first flow systems
        at resolution 64 (40 MINRES steps, all entries -> one): squash-ball (7.9M unknowns)
        109 -> 76 s, residual 1.76e-2 -> 1.74e-2, first coarse level 87M -> 35M nonzeros,
        the solve's peak 4.0 -> 3.2 GB (0.7 GB of input included); crane 18.7 -> 12.9 s,
        2.85e-2 -> 2.81e-2; dfaust-hopping 21.4 -> 14.3-15.5 s, 8.52e-3 -> 8.47e-3. But the
        flow method's squash-ball output came out worse with it (``Options``).
    coarse_drop : float
        With ``inner="amg"``: drop the weak entries of the coarse matrices, lumped onto their
        diagonals (:func:`amg_hierarchy`; 0: none). Measured on the first flow systems at
        resolution 64 (40 MINRES steps): squash-ball 0 -> 0.05: 95.8 -> 77.8 s, residual
        1.76e-2 -> 1.82e-2, first coarse level 87M -> 16M nonzeros; crane 0 -> 0.02 / 0.05:
        17.6 -> 16.2 / 14.6 s, 2.85e-2 -> 2.96e-2 / 2.99e-2 (0.1: 64 s, the coarsening
        stalls).
    overwrite_x0 : bool
        Iterate in ``x0``'s memory (float64 [n + m]) instead of a copy.
    groups : int array [n], optional
        With ``inner="amg"``: the time slice of every primal unknown. The V-cycle's
        Gauss-Seidel sweeps then run on all cores, colouring blocks of slices that share no
        entry (:mod:`.sweeps`; the same sweeps in another row order).

    Examples
    --------
    >>> import scipy.sparse as sp, numpy as np
    >>> A = sp.diags([2.0, 2.0, 2.0]).tocsr(); B = sp.csr_matrix(np.array([[1.0, 1.0, 1.0]]))
    >>> s = solve_saddle(A, B, np.zeros(3), np.array([3.0]))
    >>> bool(np.allclose(s.u, 1.0, atol=1e-3))
    True
    """
    start = time.perf_counter()
    A = sp.csr_matrix(A)
    B = sp.csr_matrix(B)
    n, m = A.shape[0], B.shape[0]
    BT = B.T
    counter = [0]
    interpolations = coarse_matrices = finest = None
    # B^T in single precision (the finest level's C) is B^T itself when B's entries are
    # single-precision numbers (the flow systems': +-1): then C's rows serve the products
    # with B^T, and B's rows those with C^T
    exact = gamma == 1.0 and np.array_equal(B.data.astype(np.float32), B.data)
    if inner == "amg":
        if reuse and reuse_coarse is not None:
            ml = frozen_hierarchy(reuse, reuse_coarse)
            finest = normal_finest(A, _normal_factor(BT, gamma), groups, B if exact else None)
        else:
            # one V-cycle is a rough inverse anyway: on the coarse levels, in single
            # precision, it costs 16% less per MINRES step with the same residual (captured
            # crane system: 60 steps 9.3 -> 7.8 s, residual 1.1e-2 both)
            S = _inner_matrix(A, B, gamma, np.float32)
            if reuse is None:
                ml = amg_hierarchy(
                    S, max_coarse=_AMG_SETUP["max_coarse"],
                    interpolation_entries=interpolation_entries, coarse_drop=coarse_drop,
                )
            else:
                ml = restricted_hierarchy(S, reuse, coarse_drop)
            if len(ml.levels) > 1:
                # the finest level sweeps A + B^T B / gamma through A and B^T (in b's double
                # precision), and S is freed
                ml.levels[0].A = None
                del S
                release_free_heap()
                finest = normal_finest(A, _normal_factor(BT, gamma), groups, B if exact else None)
        if groups is not None and len(ml.levels) > 2:
            parallel_smoothers(ml, groups)
        interpolations = tuple(level.P for level in ml.levels[:-1])
        coarse_matrices = tuple(level.A for level in ml.levels[1:]) or None

        def inner_apply(r, out):
            counter[0] += 1
            if finest is None:
                out[:] = v_cycle(ml, r.astype(np.float32))
                return out
            return v_cycle(ml, r, finest, out)

    else:
        S = _inner_matrix(A, B, gamma, np.float64)
        inner_solve = _inner_operator(S, inner, inner_rtol, counter, inner_maxiter)

        def inner_apply(r, out):
            out[:] = inner_solve(r)
            return out

    BT_rows = finest.C if exact and finest is not None else BT

    def apply_K(z, out):
        return _saddle_apply(A, B, BT_rows, softness, z, out)

    def apply_M(r, out):
        inner_apply(r[:n], out[:n])
        np.multiply(r[n:], 1.0 / gamma, out=out[n:])
        return out

    b = np.concatenate([f, g])  # after the set-up, whose peak is the solve's
    outer = [0]

    def tick(_):
        outer[0] += 1

    if np.linalg.norm(b) == 0 and x0 is None:
        return SaddleSolution(
            np.zeros(n), np.zeros(m), 0, 0, 0.0, True, time.perf_counter() - start,
            interpolations, coarse_matrices,
        )
    # MINRES measures convergence in the preconditioned norm, against an estimate of
    # ||K|| ||z||; restart from the iterate until the true relative residual is below rtol.
    norm_b = max(np.linalg.norm(b), 1e-300)
    if x0 is None:
        z = np.zeros(n + m)
    elif overwrite_x0 and isinstance(x0, np.ndarray) and x0.dtype == np.float64:
        z = x0
    else:
        z = np.array(x0, dtype=float)

    def true_residual():
        # a temporary: MINRES holds eight vectors of this size while it runs
        work = apply_K(z, np.empty(n + m))
        np.subtract(b, work, out=work)
        return float(np.linalg.norm(work) / norm_b)

    residual = true_residual()
    while residual > rtol and outer[0] < maxiter:
        before = outer[0]
        minres_inplace(
            apply_K, apply_M, b, z, rtol=rtol * 0.5, maxiter=maxiter - outer[0], callback=tick
        )
        new_residual = true_residual()
        if outer[0] == before or new_residual > 0.999 * residual:
            residual = new_residual
            break
        residual = new_residual
    info = 0 if residual <= rtol else 1
    seconds = time.perf_counter() - start
    log.debug(
        "MINRES: n=%d m=%d, %d outer / %d inner iterations, residual %.2e, %.2fs",
        n,
        m,
        outer[0],
        counter[0],
        residual,
        seconds,
    )
    return SaddleSolution(
        z[:n], z[n:], outer[0], counter[0], residual, info == 0, seconds, interpolations,
        coarse_matrices,
    )


def _inner_matrix(A: sp.csr_matrix, B: sp.csr_matrix, gamma: float, precision) -> sp.csr_matrix:
    """``A + B^T B / gamma`` in ``precision`` (the V-cycle works in single precision, so its
    matrix is formed in it: 3.0 -> 0.8 s on the captured crane system at resolution 64, the
    same entries)."""
    B_inner = B.astype(precision)
    if gamma != 1.0:
        B_inner = B_inner * precision(1.0 / np.sqrt(gamma))
    return csr_product(B_inner.T, B_inner, add=A.astype(precision))


def _normal_factor(BT: sp.spmatrix, gamma: float) -> sp.csr_matrix:
    """``C = B^T / sqrt(gamma)`` of the finest level's ``A + C C^T``, in single precision:
    its entries are +-1 in the flow systems (exact), and the sweeps read less."""
    return (BT if gamma == 1.0 else BT * (1.0 / np.sqrt(gamma))).tocsr().astype(np.float32)
