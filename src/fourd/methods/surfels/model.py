"""A model of a range of frames during the assembly (sec. 3.2): surfel trajectories over
consecutive frames, their topology graph, and which surfels have data in which frame.

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.2 "Iterative model assembly" (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fourd.methods.surfels.match import Data, associate
from fourd.methods.surfels.state import SurfelState
from fourd.methods.surfels.topology import Topology
from fourd.methods.surfels.urshape import Urshape


@dataclass(frozen=True)
class Model:
    """Surfel trajectories over frames ``start .. start + T - 1`` of the sequence.

    state : SurfelState
        ``T`` frames of ``S`` surfels.
    topology : Topology
        ``T_S``, global over the range.
    start : int
        Sequence index of the first frame.
    observed : bool [T, S]
        Surfels with data in each frame (the nearest surfel of some point within ``eps_top``).
    urshape : Urshape or None
        The range's urshape, when it was computed (:mod:`.urshape`).
    """

    state: SurfelState
    topology: Topology
    start: int
    observed: np.ndarray
    urshape: Urshape | None = None

    def __post_init__(self):
        shape = (self.state.frames, self.state.count)
        if self.observed.shape != shape:
            raise ValueError(
                f"observed must have shape {list(shape)}, got {list(self.observed.shape)}"
            )
        if self.topology.count != self.state.count:
            raise ValueError("the topology must have one node per surfel")
        if self.urshape is not None and self.urshape.rotations.shape[:2] != shape:
            raise ValueError("the urshape must reach every frame of the model's surfels")

    @property
    def stop(self) -> int:
        """One past the sequence index of the last frame."""
        return self.start + self.state.frames


def pack_model(model: Model) -> dict[str, np.ndarray]:
    """``model`` as arrays for :mod:`fourd.cache`."""
    urshape = {}
    if model.urshape is not None:
        urshape = {
            "urshape_positions": model.urshape.positions,
            "urshape_normals": model.urshape.normals,
            "urshape_rotations": model.urshape.rotations,
        }
    surface = {} if model.topology.surface is None else {"surface": model.topology.surface}
    return urshape | surface | {
        "positions": model.state.positions,
        "normals": model.state.normals,
        "rotations": model.state.rotations,
        "edges": model.topology.edges,
        "radius": np.array(model.topology.radius),
        "start": np.array(model.start),
        "observed": model.observed,
    }


def unpack_model(arrays: dict) -> Model:
    """The :class:`Model` of :func:`pack_model`'s arrays."""
    state = SurfelState(arrays["positions"], arrays["normals"], arrays["rotations"])
    surface = arrays["surface"].astype(bool) if "surface" in arrays else None
    topology = Topology(
        arrays["edges"].astype(np.int64), state.count, float(arrays["radius"]), surface
    )
    urshape = None
    if "urshape_positions" in arrays:
        urshape = Urshape(
            arrays["urshape_positions"], arrays["urshape_normals"], arrays["urshape_rotations"]
        )
    return Model(
        state, topology, int(arrays["start"]), arrays["observed"].astype(bool), urshape
    )


def observed_surfels(state: SurfelState, data: Data, radius: float) -> np.ndarray:
    """Surfels [T, S] that are the nearest surfel of some data point of their frame within
    ``radius`` (``eps_top``, the data term's global cutoff)."""
    matches = associate(state, data, radius)
    observed = np.zeros((state.frames, state.count), dtype=bool)
    observed[data.frames[matches.active], matches.surfels[matches.active]] = True
    return observed


def surfel_subset(model: Model, keep: np.ndarray) -> Model:
    """``model`` with only the surfels ``keep`` (increasing indices [K]), in that order; the
    topology keeps the edges between them (the urshape is dropped)."""
    keep = np.asarray(keep, dtype=np.int64)
    index = np.full(model.state.count, -1, dtype=np.int64)
    index[keep] = np.arange(len(keep))
    edges = index[model.topology.edges]
    both = (edges >= 0).all(axis=1)
    surface = model.topology.surface
    state = model.state
    return Model(
        SurfelState(
            state.positions[:, keep], state.normals[:, keep], state.rotations[:, keep]
        ),
        Topology(
            edges[both], len(keep), model.topology.radius, None if surface is None else surface[both]
        ),
        model.start,
        model.observed[:, keep],
    )


def unsupported_pieces(model: Model, min_piece: int) -> np.ndarray:
    """Surfels of the pieces of ``T_S`` (connected components of its edges) with fewer than
    ``min_piece`` surfels that have no data in some frame (none of their surfels
    ``observed`` there): bool [S].

    With no neighbours to carry it, such a piece has only the acceleration prior (eq. 10)
    in a frame without data: its trajectory there is the extrapolation of its last observed
    velocity, and a piece lost early in a long take flies off along it (horse-gallop: 78
    surfels alone in the graph and 10 in pieces of 3-4, last observed 4-40 frames before the
    end, up to five diagonals away in the last frame)."""
    count = model.state.count
    if min_piece <= 1 or count == 0:
        return np.zeros(count, dtype=bool)
    edges = model.topology.edges
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(count, count))
    pieces, label = connected_components(graph, directed=False)
    seen = np.zeros((model.observed.shape[0], pieces), dtype=bool)
    frame, surfel = np.nonzero(model.observed)
    seen[frame, label[surfel]] = True
    small = np.bincount(label, minlength=pieces) < min_piece
    return (small & ~seen.all(axis=0))[label]


def without_surfels(model: Model, drop: np.ndarray) -> Model:
    """``model`` without the surfels ``drop`` (bool [S]), its urshape (when it has one)
    with them."""
    if not drop.any():
        return model
    keep = np.flatnonzero(~drop)
    urshape = model.urshape
    subset = surfel_subset(model, keep)
    if urshape is None:
        return subset
    return replace(
        subset,
        urshape=replace(
            urshape,
            positions=urshape.positions[keep],
            normals=urshape.normals[keep],
            rotations=urshape.rotations[:, keep],
        ),
    )
