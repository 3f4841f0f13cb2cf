"""Rigid prediction of the sliding's initial guess (beyond the paper): the rigid motion, one
global then one per patch, that best satisfies the tangential-motion constraints, refined by
Gauss-Newton steps against the implicit (point-to-plane ICP on ``f(., t')``).
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

#: The global rigid fit of :func:`rigid_prediction` makes no motion along the directions whose
#: curvature in the least-squares fit is below this fraction of the largest: moving the shape
#: along them hardly changes the fit (the spin of a shape of revolution), so noise alone
#: would choose the motion there, and it adds up over the frames. Measured (20k samples,
#: correspondence mean / last frame): a still, noisy spheroid (8 frames) spun about its axis,
#: 0.031 mean displacement at the last frame, 0.003 with this; squash-ball 0.064 / 0.086 ->
#: 0.025 / 0.015, touching-spheres 0.019 / 0.032 -> 0.017 / 0.025. rigid-turn turns about
#: axes at 0.004-0.006 of the largest: 0.01 took it from 0.0016 to 0.12 (squash-ball
#: 0.022 / 0.003 there), so the bound stays below it. Degeneracy-aware ICP, by truncation.
DEGENERATE_MOTION = 0.002


@numba.njit(cache=True, parallel=True)
def _patch_systems(positions, normals, residuals, weights, groups, A, b, centroids, sizes, traces):
    """Per group: centroid, RMS size, the 6x6 weighted normal equations of the linearised
    point-to-plane rigid motion (rotation part made unitless by the size) and the trace of
    the unweighted ones."""
    for g in numba.prange(groups.shape[0]):
        K = groups.shape[1]
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        for k in range(K):
            v = groups[g, k]
            c0 += positions[v, 0]
            c1 += positions[v, 1]
            c2 += positions[v, 2]
        c0 /= K
        c1 /= K
        c2 /= K
        ss = 0.0
        for k in range(K):
            v = groups[g, k]
            ss += (
                (positions[v, 0] - c0) ** 2
                + (positions[v, 1] - c1) ** 2
                + (positions[v, 2] - c2) ** 2
            )
        size = np.sqrt(ss / K) + 1e-300
        J = np.empty(6)
        trace = 0.0
        for i in range(6):
            b[g, i] = 0.0
            for j in range(6):
                A[g, i, j] = 0.0
        for k in range(K):
            v = groups[g, k]
            q0 = (positions[v, 0] - c0) / size
            q1 = (positions[v, 1] - c1) / size
            q2 = (positions[v, 2] - c2) / size
            n0 = normals[v, 0]
            n1 = normals[v, 1]
            n2 = normals[v, 2]
            J[0] = q1 * n2 - q2 * n1
            J[1] = q2 * n0 - q0 * n2
            J[2] = q0 * n1 - q1 * n0
            J[3] = n0
            J[4] = n1
            J[5] = n2
            r = residuals[v]
            wv = weights[v]
            for i in range(6):
                trace += J[i] * J[i]
                b[g, i] -= wv * J[i] * r
                for j in range(i, 6):
                    A[g, i, j] += wv * J[i] * J[j]
        for i in range(6):
            for j in range(i):
                A[g, i, j] = A[g, j, i]
        centroids[g, 0] = c0
        centroids[g, 1] = c1
        centroids[g, 2] = c2
        sizes[g] = size
        traces[g] = trace


def _rigid_increments(
    positions, normals, residuals, groups, regularization, weights=None, degenerate=0.0
):
    """Linearised point-to-plane rigid motions: for every group of vertices (rows of
    ``groups`` [G, K] indexing ``positions``) the ``(omega, c)`` minimising
    ``sum_k w_k (n_k . (omega x q_k + c) + r_k)^2 + reg |(omega, c)|^2`` with ``q_k`` the
    offsets from the group's centroid and ``reg`` relative to the unweighted system (a group
    with little weight is held near no motion), and no motion along the directions of
    ``(omega, c)`` whose eigenvalue is below ``degenerate`` times the largest. Returns
    ``omega [G, 3], c [G, 3], centroids [G, 3]``."""
    G = len(groups)
    A = np.empty((G, 6, 6))
    b = np.empty((G, 6))
    centroids = np.empty((G, 3))
    sizes = np.empty(G)
    traces = np.empty(G)
    weights = np.ones(len(positions)) if weights is None else weights
    _patch_systems(
        np.ascontiguousarray(positions, dtype=np.float64),
        np.ascontiguousarray(normals, dtype=np.float64),
        np.ascontiguousarray(residuals, dtype=np.float64),
        np.ascontiguousarray(weights, dtype=np.float64),
        np.ascontiguousarray(groups, dtype=np.int64),
        A,
        b,
        centroids,
        sizes,
        traces,
    )
    damping = regularization * traces / 6.0 + 1e-300
    if degenerate > 0:
        values, vectors = np.linalg.eigh(A)
        seen = values > degenerate * values[:, -1:]
        projected = np.einsum("gij,gi->gj", vectors, b) / (values + damping[:, None])
        x = np.einsum("gij,gj->gi", vectors, np.where(seen, projected, 0.0))
    else:
        x = np.linalg.solve(A + damping[:, None, None] * np.eye(6), b[..., None])[..., 0]
    return x[:, :3] / sizes[:, None], x[:, 3:], centroids


def _rotate(vectors, rotvecs):
    """Rodrigues: rotate ``vectors`` [M, 3] by rotation vectors ``rotvecs`` ([M, 3] or [3])."""
    rotvecs = np.broadcast_to(rotvecs, vectors.shape)
    angle = np.linalg.norm(rotvecs, axis=1, keepdims=True)
    axis = rotvecs / np.maximum(angle, 1e-300)
    cos, sin = np.cos(angle), np.sin(angle)
    return (
        vectors * cos
        + np.cross(axis, vectors) * sin
        + axis * np.einsum("ij,ij->i", axis, vectors)[:, None] * (1.0 - cos)
    )


def rigid_prediction(
    positions,
    normals,
    residuals,
    *,
    neighbours: int = 0,
    regularization: float = 1e-3,
    groups: np.ndarray | None = None,
    weights: np.ndarray | None = None,
    sample: np.ndarray | None = None,
):
    """Predicted positions from the first-order space-time constraint: a global linearised
    rigid motion, refined by local ones over the ``neighbours`` nearest vertices (beyond the
    paper: the projection of 5.1 alone only moves vertices along the normals).

    ``residuals`` are ``dt * df/dt + f`` at the vertices, ``normals`` the spatial gradients,
    ``weights`` [N] (optional) the vertices' weights in the fits. ``sample`` [S] (optional,
    global motion only): the indices of the vertices that ``normals``, ``residuals`` and
    ``weights`` belong to; the global motion fitted to them moves every vertex.
    """
    if sample is not None and (groups is not None or neighbours > 1):
        raise ValueError("sample fits the global motion only: no groups or neighbours")
    fitted = positions if sample is None else positions[sample]
    norm = np.linalg.norm(normals, axis=1)
    ok = norm > 1e-12
    safe = np.where(ok, norm, 1.0)
    unit = np.where(ok[:, None], normals / safe[:, None], 0.0)
    res = np.where(ok, residuals / safe, 0.0)
    omega, c, centroid = _rigid_increments(
        fitted,
        unit,
        res,
        np.arange(len(fitted))[None],
        regularization,
        weights,
        degenerate=DEGENERATE_MOTION,
    )
    rotation = _rotate(np.eye(3), omega[0]).T  # one global motion: a 3x3 product
    moved = (positions - centroid[0]) @ rotation.T + (centroid[0] + c[0])
    if groups is not None or (neighbours > 1 and len(positions) > neighbours):
        res = res + np.einsum("ij,ij->i", unit, moved - positions)
        if groups is None:
            _, groups = cKDTree(moved).query(moved, k=neighbours, workers=-1)
        omega, c, centroid = _rigid_increments(moved, unit, res, groups, regularization, weights)
        moved = centroid + _rotate(moved - centroid, omega) + c
    return moved
