"""The 4D priors: local rigidity between consecutive frames (eq. 9, on the neighbour offsets
and on the normals), or between the urshape and every frame (sec. 3.2 "Global Optimization and
the Urshape"), and little acceleration along the trajectories (eq. 10, positions and normals);
and the initial local rotations (a least-squares fit per neighbourhood).

Each term returns a :class:`~.term.Term` over the unknowns of :class:`~.state.Layout`, summed
over all of its steps or triples of frames or over those given (a local optimisation leaves
out those that do not move, constants); given the ``pattern`` of an earlier call on the same
topology, layout and steps, only the Jacobian's values are assembled.

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.1 "Spatio-temporal smoothness", "Temporal smoothness" (``001_3fedd1c3a0ac4198.txt``).
Horn: Closed-form solution of absolute orientation using unit quaternions, JOSA A 4(4), 1987
(the initial rotations; here by the polar decomposition, :mod:`fourd.geometry.rotations`).
"""

from __future__ import annotations

import numba
import numpy as np

from fourd.geometry.rotations import best_rotations
from fourd.methods.surfels.state import SurfelState, at_surfels, layout, tangent_basis
from fourd.methods.surfels.term import Blocks, Pattern, Term, term
from fourd.methods.surfels.topology import Topology


def rigid_term(
    state: SurfelState,
    topology: Topology,
    weight: float,
    normal_weight: float = 0.0,
    *,
    derivatives: bool = True,
    urshape: bool = False,
    pattern: Pattern | None = None,
    steps: np.ndarray | None = None,
) -> Term:
    """Eq. (9): ``w sum_{t < T-1} sum_i sum_{j in N(i)} |A_i^t (s_i^t - s_j^t) - (s_i^{t+1} -
    s_j^{t+1})|^2`` plus the same potential on the normals, ``w_n sum |A_i^t n_i^t -
    n_i^{t+1}|^2`` (each surfel's own normal), over the steps ``t`` in ``steps`` (int [K];
    default all ``T - 1``). Residuals ``[K, 2E, 3]`` then ``[K, S, 3]``; the rotations enter
    as ``(I + C) A`` (eq. 12).

    With ``urshape`` frame 0 is the urshape and ``A_i^t`` maps it to frame ``t + 1``: every
    pair is ``(0, t + 1)`` instead of ``(t, t + 1)``, and consecutive frames are not tied
    (sec. 3.2, "Global Optimization and the Urshape")."""
    lay = layout(state)
    i, j = topology.directed.T
    step = (
        np.arange(state.frames - 1) if steps is None else np.asarray(steps, dtype=np.int64)
    )
    count = len(step)
    origin = np.zeros(count, dtype=np.int64) if urshape else step
    with_normals = normal_weight > 0 and count > 0
    if derivatives and pattern is None:
        pattern = _rigid_pattern(lay, i, j, step, origin, with_normals)
    if derivatives and not _rigid_fits(pattern, count, len(i), state.count, with_normals):
        raise ValueError(
            "the blocks do not match the pattern's: a pattern fits only the term, topology "
            "and layout it was made for"
        )
    edge_residuals = np.empty((count, len(i), 3))
    normal_residuals = np.empty((count, state.count, 3))
    data = np.empty(pattern.nnz + 1 if derivatives else 0)
    basis = tangent_basis(state.normals) if derivatives and with_normals else _NO_BASIS
    slots = pattern.slots if derivatives else _NO_SLOTS
    _rigid_fill(
        state.positions, state.normals, state.rotations, basis, step, origin,
        i.astype(np.int64), j.astype(np.int64), np.sqrt(weight), np.sqrt(normal_weight),
        edge_residuals, normal_residuals, data, *_padded(slots), derivatives, with_normals,
    )
    residuals = np.concatenate([edge_residuals.ravel(), normal_residuals.ravel()])
    if not derivatives:
        return term(residuals, None)
    return term(residuals, pattern.jacobian(data), pattern=pattern)


_NO_BASIS = np.zeros((0, 0, 3, 2))
_NO_SLOTS = ()


#: The shapes of the slots of :func:`_rigid_pattern`'s blocks after their leading ``[steps,
#: edges]`` (the rigidity's five) and ``[steps, surfels]`` (the normals' three), in add order:
#: a rotation's six off-diagonal entries, 3 x 3 positions, a diagonal's three, 3 x 2 offsets.
_EDGE_BLOCKS = ((6,), (3, 3), (3, 3), (3,), (3,))
_NORMAL_BLOCKS = ((6,), (3, 2), (3, 2))


def _padded(slots: tuple) -> tuple:
    """The eight slot arrays :func:`_rigid_fill` takes: the rigidity's five blocks, then the
    normals' three (empty ones where the pattern has none)."""
    dtype = slots[0].dtype if slots else np.int64
    shapes = [(0, 0, *block) for block in _EDGE_BLOCKS + _NORMAL_BLOCKS]
    return tuple(slots) + tuple(np.zeros(shape, dtype) for shape in shapes[len(slots):])


def _rigid_pattern(lay, i, j, step, origin, with_normals: bool) -> Pattern:
    """The Jacobian's structure of :func:`rigid_term`: per step and directed edge the rotation
    (its cross-product matrix, off the diagonal), both surfels' positions at the origin frame
    (3 x 3) and at the end frame (the diagonal); per step and surfel, with the normals, the
    rotation and the normal offsets at both frames (3 x 2)."""
    count, surfels = len(step), np.arange(lay.count)
    rows_count = 3 * count * (len(i) + lay.count)
    blocks = Blocks(rows_count, lay.size)
    t, o = step[:, None], origin[:, None]
    rows = 3 * np.arange(count * len(i)).reshape(count, len(i))
    full, diagonal = np.ones((3, 3)), np.eye(3, dtype=bool)
    blocks.add(rows, lay.rotation(t, i), full, ~diagonal)
    blocks.add(rows, lay.position(o, i), full)
    blocks.add(rows, lay.position(o, j), full)
    blocks.add(rows, lay.position(t + 1, i), full, diagonal)
    blocks.add(rows, lay.position(t + 1, j), full, diagonal)
    if with_normals:
        rows = 3 * count * len(i) + 3 * (np.arange(count)[:, None] * lay.count + surfels)
        tangent = np.ones((3, 2))
        blocks.add(rows, lay.rotation(t, surfels), full, ~diagonal)
        blocks.add(rows, lay.normal(o, surfels), tangent)
        blocks.add(rows, lay.normal(t + 1, surfels), tangent)
    return blocks.pattern()


def _rigid_fits(pattern: Pattern, count: int, edges: int, surfels: int, with_normals: bool) -> bool:
    """Whether ``pattern`` has the blocks :func:`_rigid_pattern` makes for these sizes."""
    shapes = [(count, edges, *block) for block in _EDGE_BLOCKS]
    if with_normals:
        shapes += [(count, surfels, *block) for block in _NORMAL_BLOCKS]
    return [s.shape for s in pattern.slots] == shapes


@numba.njit(cache=True, parallel=True, nogil=True)
def _rigid_fill(
    positions, normals, rotations, basis, step, origin, i, j, root, root_n,
    edge_residuals, normal_residuals, data,
    s_turn, s_start_i, s_start_j, s_end_i, s_end_j, s_normal_turn, s_normal_start,
    s_normal_end, derivatives, with_normals,
):
    """:func:`rigid_term`'s residuals and, with ``derivatives``, its Jacobian's values
    written straight into the CSR values ``data`` at the pattern's slots (one pass; the
    blocks gathered, multiplied and scattered by numpy took six times as long on the crane
    urshape's system)."""
    edges = len(i)
    for k in numba.prange(len(step) * edges):
        t, e = k // edges, k % edges
        a, b = i[e], j[e]
        s, o = step[t], origin[t]
        turn = rotations[s, a]
        predicted = _turned(turn, positions[o, a] - positions[o, b])
        for r in range(3):
            edge_residuals[t, e, r] = root * (
                predicted[r] - (positions[s + 1, a, r] - positions[s + 1, b, r])
            )
        if derivatives:
            _skew_into(data, s_turn[t, e], predicted, root)
            for r in range(3):
                for c in range(3):
                    data[s_start_i[t, e, r, c]] = root * turn[r, c]
                    data[s_start_j[t, e, r, c]] = -root * turn[r, c]
                data[s_end_i[t, e, r]] = -root
                data[s_end_j[t, e, r]] = root
    surfels = normals.shape[1]
    for k in numba.prange(len(step) * surfels):
        t, a = k // surfels, k % surfels
        s, o = step[t], origin[t]
        turn = rotations[s, a]
        turned = _turned(turn, normals[o, a])
        for r in range(3):
            normal_residuals[t, a, r] = root_n * (turned[r] - normals[s + 1, a, r])
        if derivatives and with_normals:
            _skew_into(data, s_normal_turn[t, a], turned, root_n)
            for r in range(3):
                for c in range(2):
                    total = 0.0
                    for m in range(3):
                        total += turn[r, m] * basis[o, a, m, c]
                    data[s_normal_start[t, a, r, c]] = root_n * total
                    data[s_normal_end[t, a, r, c]] = -root_n * basis[s + 1, a, r, c]


@numba.njit(cache=True, inline="always")
def _turned(turn, vector):
    """``turn @ vector`` (3 x 3 by [3]), summed in column order."""
    out = np.empty(3)
    for r in range(3):
        total = 0.0
        for c in range(3):
            total += turn[r, c] * vector[c]
        out[r] = total
    return out


@numba.njit(cache=True, inline="always")
def _skew_into(data, slots, vector, root):
    """``-root skew(vector)`` (:func:`~.state.skew`) off its diagonal, row by row, at ``slots``
    [6] (eq. 12: the derivative of ``(I + C) A x`` by the rotation vector of ``C``)."""
    data[slots[0]] = root * vector[2]
    data[slots[1]] = -root * vector[1]
    data[slots[2]] = -root * vector[2]
    data[slots[3]] = root * vector[0]
    data[slots[4]] = root * vector[1]
    data[slots[5]] = -root * vector[0]


def accel_term(
    state: SurfelState,
    weight: float,
    normal_weight: float = 0.0,
    *,
    derivatives: bool = True,
    first: int = 0,
    pattern: Pattern | None = None,
    centres: np.ndarray | None = None,
) -> Term:
    """Eq. (10): ``w sum_{first < t < T-1} sum_i |s_i^{t-1} - 2 s_i^t + s_i^{t+1}|^2`` plus the
    same on the normals with ``normal_weight``, over the middle frames ``t`` in ``centres``
    (int [C]; default all ``T - 2 - first``); residuals ``[C, S, 3]`` twice. ``first`` 1
    leaves out frame 0 when it is the urshape (not a point in time)."""
    lay = layout(state)
    root, root_n = np.sqrt(weight), np.sqrt(normal_weight)
    if centres is None:
        p, n = state.positions[first:], state.normals[first:]
        inner = max(state.frames - first - 2, 0)
        position_residuals = root * (p[:-2] - 2 * p[1:-1] + p[2:])
        normal_residuals = root_n * (n[:-2] - 2 * n[1:-1] + n[2:])
        centres = np.arange(first + 1, first + 1 + inner)
    else:
        centres = np.asarray(centres, dtype=np.int64)
        inner = len(centres)
        p, n = state.positions, state.normals
        position_residuals = root * (p[centres - 1] - 2 * p[centres] + p[centres + 1])
        normal_residuals = root_n * (n[centres - 1] - 2 * n[centres] + n[centres + 1])
    residuals = np.concatenate([position_residuals.ravel(), normal_residuals.ravel()])
    if not derivatives:
        return term(residuals, None)
    blocks = Blocks(residuals.size, lay.size, pattern)
    surfels = np.arange(state.count)
    rows = 3 * (np.arange(inner)[:, None] * state.count + surfels)
    t = centres[:, None]
    eye = np.eye(3)
    for shift, factor in ((-1, 1.0), (0, -2.0), (1, 1.0)):
        blocks.add(rows, lay.position(t + shift, surfels), root * factor * eye, eye > 0)
    if normal_weight > 0 and inner > 0:
        basis = tangent_basis(state.normals)
        rows = rows + position_residuals.size
        for shift, factor in ((-1, 1.0), (0, -2.0), (1, 1.0)):
            blocks.add(
                rows, lay.normal(t + shift, surfels), root_n * factor * basis[t[:, 0] + shift]
            )
    return term(residuals, blocks)


def fit_rotations(
    positions: np.ndarray, topology: Topology, *, urshape: bool = False
) -> np.ndarray:
    """The rotations [T-1, S, 3, 3] best mapping each surfel's neighbour offsets from frame
    ``t`` (frame 0, the urshape, with ``urshape``) to ``t + 1`` (eq. 9 minimised over ``A``
    alone); identity without neighbours."""
    positions = np.asarray(positions, dtype=np.float64)
    i, j = topology.directed.T
    origin = np.zeros(len(positions) - 1, dtype=np.int64) if urshape else np.arange(len(positions) - 1)
    start, end = positions[origin], positions[1:]
    before = at_surfels(start, i) - at_surfels(start, j)
    after = at_surfels(end, i) - at_surfels(end, j)
    covariances = np.zeros((len(positions) - 1, topology.count, 3, 3))
    np.add.at(covariances, (slice(None), i), before[..., :, None] * after[..., None, :])
    rotations = best_rotations(covariances.reshape(-1, 3, 3)).reshape(covariances.shape)
    lonely = topology.degrees == 0
    rotations[:, lonely] = np.eye(3)
    return rotations
