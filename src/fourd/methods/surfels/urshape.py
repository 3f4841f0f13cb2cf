"""The urshape (sec. 3.2, "Global Optimization and the Urshape"): a latent rest state that
deforms least, in the rigidity prior's sense, into every frame.

An empty frame (no data points) is initialised with the first frame and joined to every frame
of the range: the rigidity potential (eq. 9) is evaluated between each surfel of the urshape
and the same surfel in each frame, and the potentials between consecutive frames are dropped.
The urshape and the trajectories are then optimised together with the full energy (the data
in every frame keeps the initialisation from leaving artifacts). The result is an "average"
template of the range, and the trajectories pulled towards it, which the paper found to
remove correspondence noise and drift.

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.2 (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from fourd.methods.surfels.energy import Weights
from fourd.methods.surfels.match import Data, MatchOptions
from fourd.methods.surfels.motion import fit_rotations
from fourd.methods.surfels.optimizer import (
    GaussNewtonOptions,
    Optimization,
    free_unknowns,
    gauss_newton,
)
from fourd.methods.surfels.state import SurfelState, layout
from fourd.methods.surfels.topology import Topology


@dataclass(frozen=True)
class Urshape:
    """The rest state of ``S`` surfels and how it reaches each of ``T`` frames.

    positions : float64 [S, 3]
    normals : float64 [S, 3]
        Unit.
    rotations : float64 [T, S, 3, 3]
        ``A_i^t``: the local rotation of eq. (9) from the urshape to frame ``t``.
    """

    positions: np.ndarray
    normals: np.ndarray
    rotations: np.ndarray

    def __post_init__(self):
        count = len(self.positions)
        if self.positions.shape != (count, 3) or self.normals.shape != (count, 3):
            raise ValueError("urshape positions and normals must be [S, 3]")
        if self.rotations.ndim != 4 or self.rotations.shape[1:] != (count, 3, 3):
            raise ValueError(f"urshape rotations must be [T, {count}, 3, 3]")


class UrshapeFit(NamedTuple):
    """The result of :func:`fit_urshape`.

    state : SurfelState
        The trajectories after the joint optimisation; their rotations between consecutive
        frames are composed from the urshape's (``A^(t) = A_u^(t+1) (A_u^(t))^T``).
    urshape : Urshape
    optimization : Optimization
        The joint optimisation (frame 0 of its state is the urshape).
    """

    state: SurfelState
    urshape: Urshape
    optimization: Optimization


def fit_urshape(
    state: SurfelState,
    topology: Topology,
    data: Data,
    weights: Weights | None = None,
    match: MatchOptions | None = None,
    options: GaussNewtonOptions | None = None,
    *,
    joint: bool = True,
) -> UrshapeFit:
    """The urshape of ``state``'s trajectories and the trajectories optimised with it (module
    docstring). ``data`` holds the points of ``state``'s frames (frame indices
    ``0 .. T - 1``); ``weights``, ``match`` and ``options`` as for
    :func:`~.optimizer.gauss_newton`. ``joint`` False holds the trajectories: only the
    urshape and its rotations move (the rest shape of trajectories taken as final; the
    optimisation then leaves out the data, the acceleration and the frames' shape priors,
    constants)."""
    positions = np.concatenate([state.positions[:1], state.positions])
    normals = np.concatenate([state.normals[:1], state.normals])
    joined = SurfelState(positions, normals, fit_rotations(positions, topology, urshape=True))
    shifted = replace(
        data,
        frames=data.frames + 1,
        anchors=None if data.anchors is None else data.anchors.shifted(1),
        guides=None if data.guides is None else data.guides.shifted(1),
    )
    free = None
    if not joint:
        surfels = np.zeros((joined.frames, joined.count), dtype=bool)
        surfels[0] = True
        rotations = np.ones((joined.frames - 1, joined.count), dtype=bool)
        free = free_unknowns(layout(joined), surfels, rotations)
    result = gauss_newton(
        joined, topology, shifted, weights, match, options, free=free, urshape=True
    )
    fitted = result.state
    reach = fitted.rotations
    trajectories = state
    if joint:
        consecutive = reach[1:] @ np.swapaxes(reach[:-1], -1, -2)
        trajectories = SurfelState(fitted.positions[1:], fitted.normals[1:], consecutive)
    return UrshapeFit(
        trajectories, Urshape(fitted.positions[0], fitted.normals[0], reach), result
    )


def with_urshape(state: SurfelState, urshape: Urshape) -> SurfelState:
    """``T + 1`` frames: the urshape, then ``state``'s frames; the rotation from the urshape
    to frame 0 is the urshape's, the others ``state``'s own (so a frame's surfels reach every
    other frame as before and the urshape as well)."""
    if urshape.rotations.shape[:2] != (state.frames, state.count):
        raise ValueError(
            f"the urshape reaches {urshape.rotations.shape[0]} frames of "
            f"{urshape.rotations.shape[1]} surfels, the state has {state.frames} of {state.count}"
        )
    return SurfelState(
        np.concatenate([urshape.positions[None], state.positions]),
        np.concatenate([urshape.normals[None], state.normals]),
        np.concatenate([urshape.rotations[:1], state.rotations]),
    )
