"""Geometric alignment of two adjacent frame ranges (sec. 3.2 "Geometric alignment"): a
non-rigid ICP built from the statistical optimisation. An auxiliary scene of two frames:
the first is the left range's last frame, held constant; the second starts as a copy of it
and is pulled by data terms (the alignment regime: 85th-percentile cutoff, 45 degree normal
test, doublets) towards the data points of the right range's first frame, while the rigidity
prior (eq. 9) keeps the deformation smooth.

The paper takes the right range's surfels as the data points; its measured points align
better (rigid-turn scanned at 128 rays, 6 degrees between frames: mean error of the aligned
surfels 0.022 with the points against 0.047 with the surfels, 0.071 before; 15 steps). The
data term is the tangent-plane distance alone here: a tangential share pins each surfel to the
data nearest its start and the alignment does not move (0.069 at ``beta = 0.05``).

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.2 (``001_3fedd1c3a0ac4198.txt``); Haehnel, Thrun, Burgard: An extension of the ICP
algorithm for modeling nonrigid objects with mobile robots, IJCAI 2003.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fourd.geometry.icp import rigid_icp
from fourd.methods.surfels.anchors import Forward, pair_anchors
from fourd.methods.surfels.energy import Weights
from fourd.methods.surfels.match import MatchOptions, frame_data
from fourd.methods.surfels.model import Model
from fourd.methods.surfels.optimizer import GaussNewtonOptions, free_unknowns, gauss_newton
from fourd.methods.surfels.part_search import PartSearch, part_search
from fourd.methods.surfels.state import layout, surfel_state

#: The rigid start keeps its rotation only when that lowers the point-to-plane rms of a
#: translation alone by more than this fraction (``rigid_icp``'s ``rotation_evidence``).
ROTATION_EVIDENCE = 0.1
#: Nor when it turns by more than this many degrees: two adjacent frames of a capture are not
#: a quarter turn apart, and such a turn is an ICP minimum that a deformation chose (a ball
#: squashing matches itself turned by 90 degrees).
MAX_START_TURN = 30.0


class Alignment(NamedTuple):
    """The left range's surfels carried into the right range's first frame.

    positions, normals : float64 [S_left, 3]
    rotations : float64 [S_left, 3, 3]
        Local rotations ``A`` from the left's last frame to the right's first (eq. 9).
    stretch : float
        Mean rigidity residual per edge over the mean squared edge length (the "stretch"
        the paper compares between the two directions).
    """

    positions: np.ndarray
    normals: np.ndarray
    rotations: np.ndarray
    stretch: float


def align_ranges(
    left: Model,
    points: np.ndarray,
    normals: np.ndarray,
    weights: Weights,
    options: GaussNewtonOptions,
    *,
    data_weight: float,
    rigid_start: bool = True,
    percentile: float = 100.0,
    parts: PartSearch | None = None,
    anchors: Forward | None = None,
) -> Alignment:
    """Align ``left``'s last frame to the data ``points`` [P, 3] (oriented ``normals``) of
    the frame after it, the right range's first (sec. 3.2): only the data term (weight
    ``data_weight`` per point, alignment regime, no tangential share) and the rigidity terms of
    ``weights`` act; returns the moved left surfels.

    With ``rigid_start`` the second frame starts from the left surfels moved by a rigid
    point-to-plane ICP onto the points (:func:`fourd.geometry.icp.rigid_icp`) instead of
    from a copy (the paper): the conjugate gradients of a step resolve the global, smooth
    part of a motion slowest, so a non-rigid alignment from a copy stops short of it. The
    rotation is kept only when it explains more of the data than a translation alone does
    (:data:`ROTATION_EVIDENCE`) and turns by less than :data:`MAX_START_TURN`: the alignment
    has no tangential pull, so a turn the surface does not determine would stay in the
    correspondences.

    ``percentile`` is the alignment regime's cutoff (:class:`~.match.MatchOptions`; the paper
    85). Between two frames of a fast motion the largest distances are those of the limbs that
    moved most, so a percentile cutoff drops exactly them and they stay behind; at 100 only
    the angle and doublet tests reject points (the outliers are gone with the tensor voting,
    the surface one frame sees and the other does not fails the doublet test).

    With ``parts``, each part of the surfels is then searched for on its own
    (:func:`.part_search.part_search`) before the non-rigid alignment: a limb that moved
    several ``eps_sampl`` is beyond the nearest-point correspondences.

    ``anchors`` (the video's, from ``left``'s last frame into the points' frame) pull the
    surfels with ``weights.anchor`` (:mod:`.anchors`), along the surface too."""
    last = left.state.frames - 1
    p, n = left.state.positions[last], left.state.normals[last]
    if rigid_start:
        fit = rigid_icp(
            p,
            points,
            normals,
            source_normals=n,
            rotation_evidence=ROTATION_EVIDENCE,
            max_turn=MAX_START_TURN,
        )
        moved, turned = p @ fit.rotation.T + fit.translation, n @ fit.rotation.T
        rotations = np.broadcast_to(fit.rotation, (len(p), 3, 3))
    else:
        moved, turned, rotations = p, n, np.broadcast_to(np.eye(3), (len(p), 3, 3))
    if parts is not None:
        found = part_search(moved, turned, left.topology, points, normals, parts)
        moved, turned = found.positions, found.normals
        rotations = found.rotations @ rotations
    state = surfel_state(np.stack([p, moved]), np.stack([n, turned]), rotations[None])
    data = frame_data(
        [np.zeros((0, 3)), points],
        normals=[np.zeros((0, 3)), normals],
        anchors=pair_anchors([anchors]),
    )
    align_weights = Weights(
        match=data_weight,
        rigid=weights.rigid,
        rigid_normal=weights.rigid_normal,
        anchor=weights.anchor,
    )
    free = np.zeros((2, state.count), dtype=bool)
    free[1] = True
    result = gauss_newton(
        state,
        left.topology,
        data,
        align_weights,
        MatchOptions(regime="alignment", percentile=percentile),
        options,
        free=free_unknowns(layout(state), free),
    )
    moved = result.state
    i, j = left.topology.directed.T
    before = moved.positions[0, i] - moved.positions[0, j]
    after = moved.positions[1, i] - moved.positions[1, j]
    predicted = np.einsum("eab,eb->ea", moved.rotations[0, i], before)
    stretch = (
        float(
            np.mean(np.sum((predicted - after) ** 2, axis=1)) / max(np.mean(before**2) * 3, 1e-300)
        )
        if len(i)
        else 0.0
    )
    return Alignment(moved.positions[1], moved.normals[1], moved.rotations[0], stretch)
