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

import numpy as np

from fourd.geometry.rotations import best_rotations
from fourd.methods.surfels.state import SurfelState, at_surfels, layout, skew, tangent_basis
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
    root, root_n = np.sqrt(weight), np.sqrt(normal_weight)
    if steps is None:
        step = np.arange(state.frames - 1)
        turns, end, end_normals = state.rotations, state.positions[1:], state.normals[1:]
    else:
        step = np.asarray(steps, dtype=np.int64)
        turns, end, end_normals = (
            state.rotations[step], state.positions[step + 1], state.normals[step + 1]
        )
    count = len(step)
    origin = np.zeros(count, dtype=np.int64) if urshape else step
    rotations = at_surfels(turns, i)
    start = state.positions[origin]
    before = at_surfels(start, i) - at_surfels(start, j)
    after = at_surfels(end, i) - at_surfels(end, j)
    predicted = np.einsum("teab,teb->tea", rotations, before)
    edge_residuals = root * (predicted - after)
    turned = np.einsum("tsab,tsb->tsa", turns, state.normals[origin])
    normal_residuals = root_n * (turned - end_normals)
    residuals = np.concatenate([edge_residuals.ravel(), normal_residuals.ravel()])
    if not derivatives:
        return term(residuals, None)
    blocks = Blocks(residuals.size, lay.size, pattern)
    t = step[:, None]
    o = origin[:, None]
    rows = 3 * np.arange(count * len(i)).reshape(count, len(i))
    eye = np.eye(3)
    diagonal = eye.astype(bool)
    blocks.add(rows, lay.rotation(t, i), -root * skew(predicted), ~diagonal)
    blocks.add(rows, lay.position(o, i), root * rotations)
    blocks.add(rows, lay.position(o, j), -root * rotations)
    blocks.add(rows, lay.position(t + 1, i), -root * eye, diagonal)
    blocks.add(rows, lay.position(t + 1, j), root * eye, diagonal)
    if normal_weight > 0 and count > 0:
        surfels = np.arange(state.count)
        rows = edge_residuals.size + 3 * (np.arange(count)[:, None] * state.count + surfels)
        basis = tangent_basis(state.normals)
        blocks.add(rows, lay.rotation(t, surfels), -root_n * skew(turned), ~diagonal)
        blocks.add(rows, lay.normal(o, surfels), root_n * turns @ basis[origin])
        blocks.add(rows, lay.normal(t + 1, surfels), -root_n * basis[step + 1])
    return term(residuals, blocks)


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
