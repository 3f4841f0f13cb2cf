"""The 3D priors of one frame at a time: surfel positions near their neighbours' tangent
planes (eq. 6), neighbouring normals alike (eq. 7), surfels at their neighbours' centroid
(eq. 8), summed over all frames (or over the ``frames`` given: a local optimisation leaves
out those that do not move, constants).

Each returns a :class:`~.term.Term` over the unknowns of :class:`~.state.Layout`; given the
``pattern`` of an earlier call on the same topology, layout and ``frames``, only the
Jacobian's values are assembled.

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.1 "Spatial smoothness" (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

import numpy as np

from fourd.methods.surfels.state import SurfelState, at_surfels, layout, tangent_basis
from fourd.methods.surfels.term import Blocks, Pattern, Term, term
from fourd.methods.surfels.topology import Topology


def smooth_position_term(
    state: SurfelState,
    topology: Topology,
    weight: float,
    *,
    derivatives: bool = True,
    pattern: Pattern | None = None,
    frames: np.ndarray | None = None,
) -> Term:
    """Eq. (6): ``w sum_t sum_i sum_{j in N(i)} <s_i - s_j, n_i>^2``; one residual per frame
    (of ``frames``, int [F]; default all) and directed edge, ``[F, 2E]``. ``weight`` in
    1 / length^2 for a dimensionless energy."""
    i, j = topology.directed.T
    root = np.sqrt(weight)
    positions, state_normals, t = _in_frames(state, frames)
    difference = at_surfels(positions, i) - at_surfels(positions, j)
    normals = at_surfels(state_normals, i)
    residuals = root * np.einsum("tea,tea->te", difference, normals)
    if not derivatives:
        return term(residuals, None)
    lay = layout(state)
    rows = np.arange(residuals.size).reshape(residuals.shape)
    blocks = Blocks(residuals.size, lay.size, pattern)
    blocks.add(rows, lay.position(t, i), root * normals[..., None, :])
    blocks.add(rows, lay.position(t, j), -root * normals[..., None, :])
    basis = at_surfels(tangent_basis(state_normals), i)
    blocks.add(
        rows, lay.normal(t, i), root * np.einsum("tea,teab->teb", difference, basis)[..., None, :]
    )
    return term(residuals, blocks)


def smooth_normal_term(
    state: SurfelState,
    topology: Topology,
    weight: float,
    *,
    derivatives: bool = True,
    pattern: Pattern | None = None,
    frames: np.ndarray | None = None,
) -> Term:
    """Eq. (7): ``w sum_t sum_i sum_{j in N(i)} |n_i - n_j|^2``; three residuals per frame
    (of ``frames``, int [F]; default all) and directed edge, ``[F, 2E, 3]`` (dimensionless
    normals: ``weight`` carries the units)."""
    i, j = topology.directed.T
    root = np.sqrt(weight)
    _, normals, t = _in_frames(state, frames)
    residuals = root * (at_surfels(normals, i) - at_surfels(normals, j))
    if not derivatives:
        return term(residuals, None)
    lay = layout(state)
    rows = 3 * np.arange(residuals.shape[0] * residuals.shape[1]).reshape(residuals.shape[:2])
    basis = tangent_basis(normals)
    blocks = Blocks(residuals.size, lay.size, pattern)
    blocks.add(rows, lay.normal(t, i), root * at_surfels(basis, i))
    blocks.add(rows, lay.normal(t, j), -root * at_surfels(basis, j))
    return term(residuals, blocks)


def laplace_term(
    state: SurfelState,
    topology: Topology,
    weight: float,
    *,
    derivatives: bool = True,
    pattern: Pattern | None = None,
    frames: np.ndarray | None = None,
) -> Term:
    """Eq. (8): ``w sum_t sum_i |s_i - mean_{j in N(i)} s_j|^2`` over surfels with neighbours;
    three residuals per frame (of ``frames``, int [F]; default all) and surfel, ``[F, S, 3]``
    (zero for surfels without)."""
    i, j = topology.directed.T
    degrees = topology.degrees
    root = np.sqrt(weight)
    share = 1.0 / np.maximum(degrees, 1)
    positions, _, t = _in_frames(state, frames)
    # the neighbours' sums by bincount over (frame, surfel) bins (np.add.at took 20 ms of a
    # 14-frame, 500-surfel evaluation): the same additions in the same order
    count = state.count
    bins = (np.arange(len(positions))[:, None] * count + i).ravel()
    shared = share[i][:, None] * at_surfels(positions, j)
    means = np.stack(
        [
            np.bincount(bins, weights=shared[..., c].ravel(), minlength=positions[..., 0].size)
            for c in range(3)
        ],
        axis=-1,
    ).reshape(positions.shape)
    linked = (degrees > 0)[:, None]
    residuals = root * np.where(linked, positions - means, 0.0)
    if not derivatives:
        return term(residuals, None)
    lay = layout(state)
    rows = 3 * (np.arange(len(positions))[:, None] * count + np.arange(count))
    eye = np.eye(3)
    diagonal = eye.astype(bool)
    blocks = Blocks(residuals.size, lay.size, pattern)
    blocks.add(
        rows,
        lay.position(t, np.arange(count)),
        root * linked[..., None] * eye,
        linked[..., None] & diagonal,
    )
    blocks.add(rows[:, i], lay.position(t, j), -root * share[i][:, None, None] * eye, diagonal)
    return term(residuals, blocks)


def _in_frames(
    state: SurfelState, frames: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``state``'s positions and normals in ``frames`` (None: all, not copied), and those
    frames' indices as a column, int [F, 1]."""
    if frames is None:
        return state.positions, state.normals, np.arange(state.frames)[:, None]
    frames = np.asarray(frames, dtype=np.int64)
    return state.positions[frames], state.normals[frames], frames[:, None]
