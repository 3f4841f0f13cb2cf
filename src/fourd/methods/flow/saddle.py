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

import numpy as np
import pyamg
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, cg, spilu

from fourd.geometry.sparse_products import csr_product, multiply_add
from fourd.methods.flow.amg import (
    _AMG_SETUP,
    amg_hierarchy,
    frozen_hierarchy,
    normal_finest,
    parallel_smoothers,
    restricted_hierarchy,
    v_cycle,
)
from fourd.methods.flow.krylov import minres_inplace

log = logging.getLogger("fourd.methods.flow.saddle")

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
    applied on all cores (:func:`~fourd.geometry.sparse_products.multiply_add`)."""
    n = A.shape[0]
    u, multipliers = z[:n], z[n:]
    top, bottom = out[:n], out[n:]
    top.fill(0)
    bottom.fill(0)
    for matrix, vector, into in ((A, u, top), (BT, multipliers, top), (B, u, bottom)):
        if sp.issparse(matrix) and matrix.format == "csr":
            multiply_add(matrix, vector, into)
        else:
            into += matrix @ vector
    if softness:
        bottom -= softness * multipliers
    return out


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
