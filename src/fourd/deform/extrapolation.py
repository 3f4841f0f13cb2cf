"""Blending weights of the anchor transformations per triangle (thesis
``004_f87f5acf96d50b57.txt``, section 2.4.2, equation 2.1).

``min sum_(i,j) phi_ij |w_i - w_j|^2`` over the weight vectors ``w_i`` [K] of the non-anchor
triangles, the anchor triangles fixed to their one-hot vectors: a Laplace problem on the dual
graph (triangles joined across their interior edges, weighted by the bending stiffness), so
the weights are barycentric with respect to the anchors and depend only on the connectivity,
the stiffness and the choice of anchors: factorised once per choice, whatever the anchors'
transformations.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fourd.errors import InputError
from fourd.geometry.meshes import face_adjacency

__all__ = ["blending_weights"]

#: Added to the diagonal (relative to the mean stiffness) so that a part of the mesh with no
#: anchor (another component) gets zero weights (the identity) instead of a singular system.
SCREEN = 1e-12


def blending_weights(
    faces: np.ndarray, bending: np.ndarray, anchors: np.ndarray, *, pairs: np.ndarray | None = None
) -> np.ndarray:
    """Weights [F, K] of ``K`` anchor triangles for every triangle (rows sum to 1 where
    connected to an anchor).

    Parameters
    ----------
    faces : int [F, 3]
    bending : float64 [E]
        Bending stiffness per interior edge (order of
        :func:`fourd.geometry.meshes.face_adjacency`).
    anchors : int [K]
        The anchor triangles (distinct face indices).
    pairs : int [E, 2], optional
        :func:`fourd.geometry.meshes.face_adjacency` of ``faces``, when already computed.

    Examples
    --------
    >>> strip = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]])
    >>> blending_weights(strip, np.ones(3), np.array([0, 3])).round(3).tolist()
    [[1.0, 0.0], [0.667, 0.333], [0.333, 0.667], [0.0, 1.0]]
    """
    faces = np.asarray(faces, dtype=np.int64)
    anchors = np.asarray(anchors, dtype=np.int64).ravel()
    count = len(faces)
    if len(anchors) == 0:
        raise InputError("material-aware deformation needs at least one anchor triangle")
    if anchors.min() < 0 or anchors.max() >= count or len(np.unique(anchors)) != len(anchors):
        raise InputError(f"anchor triangles must be distinct face indices below {count}")
    pairs = face_adjacency(faces)[0] if pairs is None else pairs
    bending = np.asarray(bending, dtype=np.float64)
    i, j = pairs[:, 0], pairs[:, 1]
    adjacency = sp.coo_matrix((np.r_[bending, bending], (np.r_[i, j], np.r_[j, i])), shape=(count, count)).tocsr()
    laplacian = sp.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency
    is_anchor = np.zeros(count, dtype=bool)
    is_anchor[anchors] = True
    free = np.flatnonzero(~is_anchor)
    weights = np.zeros((count, len(anchors)))
    weights[anchors, np.arange(len(anchors))] = 1.0
    if len(free):
        screen = SCREEN * max(float(bending.mean()) if len(bending) else 1.0, 1e-300)
        system = laplacian[free][:, free] + screen * sp.identity(len(free))
        rhs = -(laplacian[free][:, anchors] @ np.eye(len(anchors)))
        weights[free] = spla.splu(system.tocsc()).solve(np.asarray(rhs))
    return weights
