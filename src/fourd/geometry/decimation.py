"""A coarser version of a mesh and the carrying of displacements from it back to the mesh.

The coarse mesh is quadric edge-collapse decimation (Garland and Heckbert 1997, by the
``fast_simplification`` package), which keeps the shape and the borders of holes. A
displacement field found on the coarse mesh reaches the fine vertices by inverse-distance
weights of their nearest coarse vertices at rest: smooth fields (a limb's rigid motion seen
over a few coarse edges) come back to second order in the coarse spacing.

References
----------
M. Garland, P. S. Heckbert, "Surface simplification using quadric error metrics",
SIGGRAPH 1997.
"""

from __future__ import annotations

from typing import NamedTuple

import fast_simplification
import numpy as np
from scipy.spatial import cKDTree

#: Nearest coarse vertices each fine vertex takes its displacement from.
CARRY_NEIGHBOURS = 4


class Coarse(NamedTuple):
    """A decimated mesh and how its fine mesh follows it.

    vertices : float64 [M, 3]
    faces : int64 [G, 3]
    nearest : int64 [N, K]
        Each fine vertex's nearest coarse vertices at rest.
    weights : float64 [N, K]
        Their inverse-distance weights (rows sum to 1).
    """

    vertices: np.ndarray
    faces: np.ndarray
    nearest: np.ndarray
    weights: np.ndarray

    def carry(self, moved: np.ndarray) -> np.ndarray:
        """The fine vertices' displacements ``[N, 3]`` from the coarse vertices moved to
        ``moved [M, 3]``."""
        return np.einsum("nk,nkd->nd", self.weights, (moved - self.vertices)[self.nearest])


def decimate(vertices: np.ndarray, faces: np.ndarray, reduction: float) -> Coarse:
    """The mesh with about ``reduction`` of its faces collapsed away (0.75: a quarter left,
    edges about twice as long), with the fine vertices' carrying weights.

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
    reduction : float
        In (0, 1).
    """
    if not 0.0 < reduction < 1.0:
        raise ValueError(f"reduction must lie in (0, 1), got {reduction}")
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    coarse, coarse_faces = fast_simplification.simplify(vertices, faces, target_reduction=float(reduction))
    coarse = np.asarray(coarse, dtype=np.float64)
    used = np.unique(coarse_faces)
    remap = np.full(len(coarse), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    coarse, coarse_faces = coarse[used], remap[np.asarray(coarse_faces, dtype=np.int64)]
    k = min(CARRY_NEIGHBOURS, len(coarse))
    distance, nearest = cKDTree(coarse).query(vertices, k=k)
    distance, nearest = distance.reshape(len(vertices), k), nearest.reshape(len(vertices), k)
    weights = 1.0 / np.maximum(distance, 1e-300)  # a fine vertex on a coarse one takes its motion
    weights /= weights.sum(axis=1, keepdims=True)
    return Coarse(coarse, coarse_faces, nearest, weights)
