"""Resampling after a merge (sec. 3.2 "Resampling"): greedily delete every surfel that is
unnecessary, i.e. within ``eps_sampl / 2`` of another surfel in *all* frames, unless it is
the last surfel supporting one already deleted; then the topology is rebuilt from scratch.

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.2 (``001_3fedd1c3a0ac4198.txt``); Wand: Point-based multi-resolution rendering,
PhD thesis, Tuebingen 2004 (the greedy sampling).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def redundant_surfels(
    positions: np.ndarray, radius: float, *, priority: np.ndarray | None = None
) -> np.ndarray:
    """Surfels to delete (bool [S]) from trajectories ``positions`` [T, S, 3]: visiting the
    surfels by decreasing ``priority`` [S] (default: index order), each one not yet deleted
    is kept and deletes every undecided surfel that stays within ``radius`` of it in every
    frame; a kept surfel is never deleted, so each deleted one has a kept one beside it."""
    positions = np.asarray(positions, dtype=np.float64)
    count = positions.shape[1]
    pairs = cKDTree(positions[0]).query_pairs(radius, output_type="ndarray").reshape(-1, 2)
    if len(pairs):
        far = np.linalg.norm(positions[:, pairs[:, 0]] - positions[:, pairs[:, 1]], axis=-1).max(
            axis=0
        )
        pairs = pairs[far < radius]
    order = (
        np.arange(count) if priority is None else np.argsort(-np.asarray(priority), kind="stable")
    )
    both = np.concatenate([pairs, pairs[:, ::-1]])
    both = both[np.argsort(both[:, 0], kind="stable")]
    starts = np.searchsorted(both[:, 0], np.arange(count + 1))
    status = np.zeros(count, dtype=np.int8)  # 0 undecided, 1 kept, 2 deleted
    partners = both[:, 1]
    for surfel in order:
        if status[surfel]:
            continue
        status[surfel] = 1
        near = partners[starts[surfel] : starts[surfel + 1]]
        near = near[status[near] == 0]
        status[near] = 2
    return status == 2
