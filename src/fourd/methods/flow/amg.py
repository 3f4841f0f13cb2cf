"""Algebraic multigrid for the inner SPD system ``A + B^T B / gamma`` of the flow's saddle
solve: Ruge-Stueben hierarchies with direct interpolation, hierarchies restricted to the
unknowns still free or frozen from an earlier set-up, and a symmetric V-cycle whose
Gauss-Seidel sweeps run on all cores (:mod:`.sweeps`), the finest level swept through ``A``
and ``B^T`` without forming their product (:class:`NormalFinest`).
"""


from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
from pyamg import amg_core
from pyamg.multilevel import MultilevelSolver
from pyamg.relaxation.smoothing import change_smoothers

from fourd.geometry.sparse_products import galerkin_product, multiply_add, unsigned
from fourd.methods.flow import sweeps
from fourd.methods.flow.sparse import (
    drop_weak_entries,
    principal_submatrix,
    strong_pattern,
    strong_values,
    submatrix,
    transpose_pattern,
    truncate_rows,
    used_columns,
)

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


def _multilevel(levels: list, A: sp.csr_matrix) -> MultilevelSolver:
    """The solver of ``levels`` (with ``A``, ``P``, ``R``) and the coarsest matrix ``A``."""
    coarsest = MultilevelSolver.Level()
    coarsest.A = A
    ml = MultilevelSolver([*levels, coarsest], coarse_solver="pinv")
    change_smoothers(ml, list(_PRESMOOTHERS), list(_POSTSMOOTHERS))
    return ml


def _level(A: sp.csr_matrix, P: sp.csr_matrix, coarse_drop: float = 0.0):
    """One level of a hierarchy and the next coarser matrix, the Galerkin product ``P^T A P``
    (on all cores, without ``A P``:
    :func:`~fourd.geometry.sparse_products.galerkin_product`), its weak entries lumped onto
    its diagonal if ``coarse_drop`` > 0 (:func:`.sparse.drop_weak_entries`)."""
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
    multiply_add(level.P, coarse_x, x)
    if finest.CT is None:
        y[:] = C.T @ x
    else:
        y.fill(0)
        multiply_add(finest.CT, x, y)
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
    multiply_add(level.A, x, residual, -1.0)
    coarse_rhs = _restrict(ml, depth, residual)
    if depth == len(ml.levels) - 2:
        coarse_x = ml.coarse_solver(ml.levels[-1].A, coarse_rhs)
    else:
        coarse_x = _cycle(ml, depth + 1, coarse_rhs)
    multiply_add(level.P, coarse_x, x)
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
