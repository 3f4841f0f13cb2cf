"""Gauss-Newton on eq. (3): per step the data re-associated, the analytic Gauss-Newton
Hessian assembled sparse, the step solved by conjugate gradients with a (block-)Jacobi
preconditioner (it balances the scales of positions, normals and rotations), a backtracking
line search on the true energy, and the step retracted (normals unit, rotations orthonormal).

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.1 "Numerical optimization" (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.sparse_products import SYMMETRIC_CHUNKS, multiply_add, symmetric_multiply
from fourd.methods.surfels.energy import Weights, total_energy
from fourd.methods.surfels.match import Data, MatchOptions, associate
from fourd.methods.surfels.state import Layout, SurfelState, layout, moving_frames, retract
from fourd.methods.surfels.term import PatternCache
from fourd.methods.surfels.topology import Topology

log = logging.getLogger("fourd.methods.surfels.optimizer")


@dataclass(frozen=True)
class GaussNewtonOptions:
    """Options of :func:`gauss_newton`.

    iterations : int
        Most Gauss-Newton steps.
    tolerance : float
        Stop when a step lowers the energy by less than this fraction.
    damping : float
        Levenberg damping: ``damping * diag(H)`` added to the Hessian.
    preconditioner : str
        ``"block"`` (inverse 3x3 / 2x2 diagonal blocks per unknown) or ``"jacobi"``.
    cg_tolerance : float
        Relative residual at which conjugate gradients stop.
    cg_iterations : int
        Most conjugate-gradient iterations per step.
    halvings : int
        Most step halvings of the line search; a step that lowers the energy at none of the
        scales down to ``2^-halvings`` ends the optimisation.
    """

    iterations: int = 30
    tolerance: float = 1e-6
    damping: float = 1e-4
    preconditioner: str = "block"
    cg_tolerance: float = 1e-6
    cg_iterations: int = 500
    halvings: int = 12

    def __post_init__(self):
        if self.preconditioner not in ("block", "jacobi"):
            raise ValueError(f"preconditioner must be block or jacobi, got {self.preconditioner!r}")
        if self.iterations < 0 or self.damping < 0 or self.halvings < 0:
            raise ValueError("iterations, damping and halvings must not be negative")


@dataclass(frozen=True)
class Optimization:
    """The outcome of :func:`gauss_newton`.

    state : SurfelState
    energies : float64 [iterations + 1]
        Energy before the first step and after each; with ``free``, of the terms' parts that
        touch a free unknown (eq. 3 up to a constant).
    cg_iterations : int64 [iterations]
    converged : bool
        The last step lowered the energy by less than the tolerance (or none could).
    """

    state: SurfelState
    energies: np.ndarray
    cg_iterations: np.ndarray
    converged: bool


def gauss_newton(
    state: SurfelState,
    topology: Topology,
    data: Data,
    weights: Weights | None = None,
    match: MatchOptions | None = None,
    options: GaussNewtonOptions | None = None,
    *,
    free: np.ndarray | None = None,
    urshape: bool = False,
    patterns: PatternCache | None = None,
) -> Optimization:
    """Minimise eq. (3) from ``state``; the data term's scale is ``topology.radius``
    (defaults: :class:`~.energy.Weights`, :class:`~.match.MatchOptions`,
    :class:`GaussNewtonOptions`).

    ``free`` (bool [:attr:`~.state.Layout.size`], see :func:`free_unknowns`) restricts the
    steps to those unknowns, the others held as boundary conditions (the assembly's
    alignment of one frame and its hole filling of new surfels only, sec. 3.2); None: all.
    The data of frames that do not move and the priors' rows that touch no free unknown are
    then left out (constants, :func:`~.energy.prior_reach`), so a local optimisation costs
    what moves. ``urshape``: frame 0 of ``state`` is the urshape (:func:`~.energy.total_energy`).
    ``patterns`` carries the priors' Jacobian patterns to later calls on the same topology,
    layout and ``urshape``, whatever their ``free``, and those of the last ``free``, for a call
    with the same ``free`` (:class:`~.term.PatternCache`)."""
    weights = weights or Weights()
    match = match or MatchOptions()
    options = options or GaussNewtonOptions()
    energies = []
    cg_counts = []
    converged = False
    columns = None if free is None else np.flatnonzero(free)
    if columns is not None and match.regime == "global":
        # the data of frames that do not move adds a constant (the alignment regime's cutoff,
        # a percentile of every distance, couples the frames)
        data = data.of_frames(moving_frames(layout(state), columns)[0])
    matches = associate(state, data, topology.radius, match)
    # the topology and layout are fixed here, and so are the priors' Jacobian patterns
    kept = {} if patterns is None else patterns.for_columns(columns)

    def derivatives_at(state, matches):
        return total_energy(
            state,
            topology,
            data,
            matches,
            weights,
            match,
            columns=columns,
            urshape=urshape,
            patterns=kept,
            shared=None if patterns is None else patterns.full,
        )

    current = derivatives_at(state, matches)
    energies.append(current.value)
    for iteration in range(options.iterations):
        step, count = solve_step(
            current.hessian,
            current.gradient,
            layout(state),
            options,
            columns=columns,
            overwrite=True,
        )
        cg_counts.append(count)
        accepted = None
        scale = 1.0
        for _ in range(options.halvings + 1):
            trial = retract(state, scale * step)
            again = associate(trial, data, topology.radius, match, previous=matches)
            value = total_energy(
                trial,
                topology,
                data,
                again,
                weights,
                match,
                derivatives=False,
                columns=columns,
                urshape=urshape,
            ).value
            if value < current.value:
                accepted = trial
                break
            scale *= 0.5
        if accepted is None:
            converged = True
            break
        # the accepted trial's association and energy are the next step's start
        state, matches = accepted, again
        energies.append(value)
        if current.value - value <= options.tolerance * max(abs(current.value), 1e-300):
            converged = True
            break
        if iteration + 1 < options.iterations:
            # derivatives only where another step follows; the last Hessian is let go first, or
            # it would live beside the next one's Jacobians (a quarter of the peak memory)
            current = None
            current = derivatives_at(state, matches)
    log.debug(
        "gauss-newton: %d steps, energy %.6g -> %.6g", len(cg_counts), energies[0], energies[-1]
    )
    return Optimization(state, np.array(energies), np.array(cg_counts, dtype=np.int64), converged)


def solve_step(
    hessian: sp.csr_matrix,
    gradient: np.ndarray,
    lay: Layout,
    options: GaussNewtonOptions,
    *,
    free: np.ndarray | None = None,
    columns: np.ndarray | None = None,
    overwrite: bool = False,
) -> tuple[np.ndarray, int]:
    """The damped Gauss-Newton step ``-(H + damping diag H)^-1 g`` [n] by preconditioned CG,
    over the unknowns the energy depends on (and, given ``free`` bool [n], only those; the
    others stay 0), and the CG iteration count. ``hessian`` holds ``H``'s entries on and
    above the diagonal (:class:`~.energy.Energy`).

    With ``columns`` (int [k], sorted), ``hessian`` [k, k] and ``gradient`` [k] are already
    restricted to those unknowns of the layout (:func:`~.energy.total_energy` ``columns``).
    ``overwrite``: the damping may be written into ``hessian`` itself (no copy of it)."""
    diagonal = hessian.diagonal()
    moving = diagonal > 1e-300 * max(float(diagonal.max(initial=0.0)), 1e-300)
    if free is not None:
        moving &= np.asarray(free, dtype=bool)
    local = np.flatnonzero(moving)
    free = local if columns is None else np.asarray(columns)[local]
    step = np.zeros(lay.size)
    if not len(free):
        return step, 0
    if len(local) == hessian.shape[0]:
        system = hessian if overwrite else hessian.copy()
    else:
        system = hessian[local][:, local]
    # every moving unknown has its diagonal entry, so this changes values only
    system.setdiag((1.0 + options.damping) * diagonal[local])
    if options.preconditioner == "block":
        preconditioner = _block_jacobi(system, free, lay)
    else:
        preconditioner = sp.diags(1.0 / system.diagonal())
    solution, count = conjugate_gradients(
        system.tocsr(),
        -gradient[local],
        preconditioner.tocsr(),
        tolerance=options.cg_tolerance,
        iterations=options.cg_iterations,
    )
    step[free] = solution
    return step, count


def conjugate_gradients(
    matrix: sp.csr_matrix,
    rhs: np.ndarray,
    preconditioner: sp.csr_matrix,
    *,
    tolerance: float,
    iterations: int,
) -> tuple[np.ndarray, int]:
    """Preconditioned conjugate gradients for ``matrix x = rhs`` (``matrix`` symmetric,
    given by its entries on and above the diagonal) from ``x = 0``, stopping at
    ``|r| <= tolerance |rhs|`` or after ``iterations``; the solution and the iterations run.
    A plain loop of sparse products and ``einsum`` dots: scipy's ``cg`` spent 2.7 ms per
    iteration on its own bookkeeping against 0.5 ms for the product on a merge of 1,300
    surfels, and a threaded BLAS ``x @ x`` of 30,000 entries took 18 ms on the loaded 2-core
    machine against 14 us for ``einsum``. The products run on all cores
    (:func:`~fourd.geometry.sparse_products.symmetric_multiply` and ``multiply_add``;
    scipy's on one), with the same result on any number of them."""
    x = np.zeros_like(rhs)
    r = rhs.copy()
    goal = tolerance * np.sqrt(_dot(rhs, rhs))
    if goal == 0.0:
        return x, 0
    z = preconditioner @ r
    p = z.copy()
    q = np.empty_like(rhs)
    # the product's work rows, allocated once for every iteration
    partial = np.empty((SYMMETRIC_CHUNKS, len(rhs)))
    rz = _dot(r, z)
    done = 0
    while done < iterations:
        done += 1
        symmetric_multiply(matrix, p, q, partial)
        curvature = _dot(p, q)
        if curvature <= 0.0:
            break
        alpha = rz / curvature
        x += alpha * p
        r -= alpha * q
        if np.sqrt(_dot(r, r)) <= goal:
            break
        z.fill(0.0)
        multiply_add(preconditioner, r, z)
        rz_next = _dot(r, z)
        p *= rz_next / rz
        p += z
        rz = rz_next
    return x, done


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a . b`` without BLAS (see :func:`conjugate_gradients`)."""
    return float(np.einsum("i,i->", a, b))


def _block_jacobi(system: sp.csr_matrix, free: np.ndarray, lay: Layout) -> sp.csr_matrix:
    """Inverse diagonal blocks of ``system`` (rows and columns ``free`` of the full layout; its
    entries on and above the diagonal, or all):
    one block per unknown (3 position, 2 normal offset or 3 rotation entries), restricted to
    its free entries."""
    unknown = np.empty(lay.size, dtype=np.int64)
    bounds = [0, lay.normals_start, lay.rotations_start, lay.size]
    for start, end, size in zip(bounds[:-1], bounds[1:], (3, 2, 3), strict=True):
        unknown[start:end] = start + (np.arange(end - start) // size) * size
    # free is sorted, so each unknown's free entries are one run of the reduced system
    owner = unknown[free]
    first = np.searchsorted(owner, owner)
    member = np.arange(len(free)) - first
    _, group = np.unique(owner, return_inverse=True)
    sizes = np.bincount(group)
    blocks = np.zeros((len(sizes), 3, 3))
    # one compiled pass over the entries (scipy's diagonal(k) for the five diagonals -2 .. 2
    # that hold the blocks, each a pass over the whole system: 92 against 35 ms for the whole
    # preconditioner of a 10-million-entry system)
    _diagonal_blocks(system.indptr, system.indices, system.data, owner, group, member, blocks)
    unused = np.arange(3)[None, :] >= sizes[:, None]
    blocks[:, np.arange(3), np.arange(3)] += unused
    inverse = np.linalg.inv(blocks)
    column = np.tile(np.arange(3), len(free))
    rows = np.repeat(np.arange(len(free)), 3)
    values = inverse[group[rows], member[rows], column]
    valid = column < sizes[group[rows]]
    return sp.csr_matrix(
        (values[valid], (rows[valid], first[rows][valid] + column[valid])),
        shape=(len(free), len(free)),
    )


@numba.njit(cache=True, nogil=True)
def _diagonal_blocks(indptr, indices, data, owner, group, member, blocks):
    """``blocks[group[r], member[r], member[c]] = system[r, c]``, and its mirror, for every
    stored entry of a symmetric CSR system whose row ``r`` and column ``c`` belong to one
    unknown (``owner``)."""
    for row in range(len(indptr) - 1):
        for k in range(indptr[row], indptr[row + 1]):
            column = indices[k]
            if owner[column] == owner[row]:
                blocks[group[row], member[row], member[column]] = data[k]
                blocks[group[row], member[column], member[row]] = data[k]


def free_unknowns(
    lay: Layout, surfels: np.ndarray, rotations: np.ndarray | None = None
) -> np.ndarray:
    """The unknowns [:attr:`~.state.Layout.size`] a step may change: the position and normal
    offset of every ``(frame, surfel)`` true in ``surfels`` bool [T, S], and the rotation
    vectors true in ``rotations`` bool [T - 1, S] (default: those of surfels free in either
    frame the rotation joins)."""
    surfels = np.asarray(surfels, dtype=bool)
    if surfels.shape != (lay.frames, lay.count):
        raise ValueError(f"surfels must have shape [{lay.frames}, {lay.count}]")
    if rotations is None:
        rotations = surfels[:-1] | surfels[1:]
    rotations = np.asarray(rotations, dtype=bool)
    return np.concatenate(
        [
            np.repeat(surfels.ravel(), 3),
            np.repeat(surfels.ravel(), 2),
            np.repeat(rotations.ravel(), 3),
        ]
    )
