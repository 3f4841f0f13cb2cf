"""Per-vertex sums of weighted projectors: the normal equations of data terms
``sum_k w_k |P_k (x_{v_k} - p_k)|^2`` with ``P_k = a_k I + b_k d_k d_k^T``, the point (``a = 1,
b = 0``), plane (``a = 0, b = 1``, ``d`` the normal) and line (``a = 1, b = -1``, ``d`` the
tangent) pulls of ICP-style fits and their mixes (Li, Sumner and Pauly 2008).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np


class ProjectorSums(NamedTuple):
    """``blocks [N, 3, 3]``: per vertex ``sum_k w_k P_k``; ``right [N, 3]``: ``sum_k w_k P_k p_k``;
    ``counts [N]``: how many terms each vertex received."""

    blocks: np.ndarray
    right: np.ndarray
    counts: np.ndarray


def projector_sums(
    vertices: np.ndarray,
    points: np.ndarray,
    weights: np.ndarray | float,
    count: int,
    *,
    directions: np.ndarray | None = None,
    identity: np.ndarray | float = 1.0,
    outer: np.ndarray | float = 0.0,
) -> ProjectorSums:
    """The terms ``w_k |P_k (x_{v_k} - p_k)|^2``, ``P_k = a_k I + b_k d_k d_k^T``, summed per vertex.

    Parameters
    ----------
    vertices : int array [K]
        The vertex ``v_k`` of each term, in ``[0, count)``.
    points : array [K, 3]
        Each term's goal ``p_k``.
    weights : array [K] or float
        ``w_k``.
    count : int
        Number of vertices ``N``.
    directions : array [K, 3] or None
        Unit ``d_k`` (a plane's normal, a line's tangent); None: only ``a_k I``.
    identity, outer : array [K] or float
        ``a_k`` and ``b_k``.

    Returns
    -------
    ProjectorSums
        Summed in the order of the terms (as ``np.bincount`` would).
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.int64)
    size = len(vertices)
    points = np.ascontiguousarray(np.reshape(points, (size, 3)), dtype=np.float64)
    if directions is None:
        directions, outer = np.zeros((size, 3)), 0.0
    directions = np.ascontiguousarray(np.reshape(directions, (size, 3)), dtype=np.float64)
    weights, identity, outer = (np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=np.float64), (size,)))
                                for value in (weights, identity, outer))
    if size and (vertices.min() < 0 or vertices.max() >= count):
        raise ValueError(f"vertex ids must lie in [0, {count}); got {vertices.min()}..{vertices.max()}")
    return ProjectorSums(*_sums(vertices, points, weights, directions, identity, outer, count))


@numba.njit(cache=True, nogil=True)
def _sums(vertices, points, weights, directions, identity, outer, count):
    blocks = np.zeros((count, 3, 3))
    right = np.zeros((count, 3))
    counts = np.zeros(count, dtype=np.int64)
    q = np.empty((3, 3))
    for k in range(len(vertices)):
        v = vertices[k]
        w, a, b = weights[k], identity[k], outer[k]
        for i in range(3):
            for j in range(3):
                q[i, j] = w * (b * directions[k, i] * directions[k, j] + (a if i == j else 0.0))
        for i in range(3):
            for j in range(3):
                blocks[v, i, j] += q[i, j]
            # summed as numpy's einsum sums it (first and last term, then the middle): the
            # results of the vectorised forms this replaced, to the last bit
            right[v, i] += (q[i, 0] * points[k, 0] + q[i, 2] * points[k, 2]) + q[i, 1] * points[k, 1]
        counts[v] += 1
    return blocks, right, counts
