"""Hole filling after stitching (sec. 3.2 "Hole filling"): the trajectories that a merge
left unknown (the left range's surfels in the right range's frames and the other way round)
are grown in time one frame at a time. Each new surfel is first predicted from its known
neighbours (their local rotation applied to the offset, the rigid prediction of eq. 9), then
the new surfels of that frame alone are optimised with the full energy, every other surfel
(spatial and temporal neighbours) held as a boundary condition.

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.2 (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

import numpy as np

from fourd.methods.surfels.anchors import pair_anchors
from fourd.methods.surfels.energy import Weights
from fourd.methods.surfels.match import MatchOptions, frame_data
from fourd.methods.surfels.optimizer import GaussNewtonOptions, free_unknowns, gauss_newton
from fourd.methods.surfels.state import SurfelState, layout
from fourd.methods.surfels.term import PatternCache
from fourd.methods.surfels.topology import Topology

#: Rounds of neighbour-to-neighbour prediction before a surfel with no known neighbour is
#: simply copied from the frame before.
PREDICTION_ROUNDS = 8


def predict(
    positions: np.ndarray,
    normals: np.ndarray,
    rotations: np.ndarray,
    known: np.ndarray,
    new: np.ndarray,
    source: int,
    target: int,
    topology: Topology,
) -> None:
    """Predict the ``new`` surfels (bool [S]) in frame ``target`` from frame ``source`` (in
    place on ``positions``, ``normals`` [T, S, 3]): each neighbour ``j`` known in both frames
    (``known`` bool [T, S]) predicts ``p_j^target + R_j (p_i^source - p_j^source)`` with its
    rotation ``R_j`` between the frames (``rotations`` [T-1, S, 3, 3], transposed going
    back in time); the predictions are averaged, and surfels without any such neighbour get
    theirs from newly predicted ones over a few rounds, else a copy."""
    step = min(source, target)
    turn = rotations[step] if target > source else np.swapaxes(rotations[step], -1, -2)
    ready = known[source] & known[target]
    pending = new.copy()
    i, j = topology.directed.T
    for _ in range(PREDICTION_ROUNDS):
        use = pending[i] & ready[j]
        if not use.any():
            break
        a, b = i[use], j[use]
        offset = positions[source, a] - positions[source, b]
        guess = positions[target, b] + np.einsum("eab,eb->ea", turn[b], offset)
        normal = np.einsum("eab,eb->ea", turn[b], normals[source, a])
        count = np.bincount(a, minlength=len(pending)).astype(np.float64)
        done = count > 0
        for axis in range(3):
            positions[target, done, axis] = (
                np.bincount(a, guess[:, axis], minlength=len(pending))[done] / count[done]
            )
            normals[target, done, axis] = np.bincount(a, normal[:, axis], minlength=len(pending))[
                done
            ]
        normals[target, done] /= np.maximum(
            np.linalg.norm(normals[target, done], axis=1, keepdims=True), 1e-300
        )
        ready = ready | done
        pending &= ~done
    positions[target, pending] = positions[source, pending]
    normals[target, pending] = normals[source, pending]


def fill_holes(
    state: SurfelState,
    known: np.ndarray,
    topology: Topology,
    frames: list,
    weights: Weights,
    options: GaussNewtonOptions,
    match: MatchOptions | None = None,
) -> SurfelState:
    """Fill the unknown trajectory entries (``~known`` bool [T, S]) of ``state`` by region
    growing in time, forward then backward (sec. 3.2): per frame, predict the surfels known in
    the frame before (after) but not in this one, then optimise them alone against this
    frame's data (``frames[t].points``/``.normals``) and the priors, everything else fixed."""
    known = np.asarray(known, dtype=bool).copy()
    positions = state.positions.copy()
    normals = state.normals.copy()
    rotations = state.rotations.copy()
    count = state.count
    # the priors' Jacobian patterns, the same for every window of one length
    patterns: dict[int, PatternCache] = {}
    for direction in (1, -1):
        order = range(1, state.frames) if direction > 0 else range(state.frames - 2, -1, -1)
        for t in order:
            source = t - direction
            new = known[source] & ~known[t]
            if not new.any():
                continue
            predict(positions, normals, rotations, known, new, source, t, topology)
            window = sorted({max(0, min(state.frames - 1, t - direction * k)) for k in range(3)})
            local = SurfelState(
                positions[window].copy(),
                normals[window].copy(),
                rotations[window[0] : window[-1]].copy(),
            )
            free = np.zeros((len(window), count), dtype=bool)
            at = window.index(t)
            free[at] = new
            moving_rotation = np.zeros((len(window) - 1, count), dtype=bool)
            moving_rotation[min(at, window.index(source))] = new
            data = frame_data(
                [frames[w].points if w == t else np.zeros((0, 3)) for w in window],
                normals=[frames[w].normals if w == t else np.zeros((0, 3)) for w in window],
                anchors=pair_anchors([frames[w].forward for w in window[:-1]]),
            )
            result = gauss_newton(
                local,
                topology,
                data,
                weights,
                match,
                options,
                free=free_unknowns(layout(local), free, moving_rotation),
                patterns=patterns.setdefault(len(window), PatternCache()),
            )
            positions[t] = result.state.positions[at]
            normals[t] = result.state.normals[at]
            rotations[window[0] : window[-1]] = result.state.rotations
            known[t] |= new
    return SurfelState(positions, normals, rotations)
