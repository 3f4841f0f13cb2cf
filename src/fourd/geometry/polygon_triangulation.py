"""Triangulating the inside of a plane polygon with triangles of about one edge length.

The polygon's points are kept as they are (the first points of the result, in order); points
of a triangular lattice inside it, farther than 0.6 edge lengths from the outline, are added;
the Delaunay triangles whose centres lie inside are kept. Where the Delaunay triangulation
does not follow an outline edge (a thin or strongly concave polygon), the polygon is
triangulated by ear clipping from its own points instead, so every outline edge is always an
edge of exactly one triangle.

Examples
--------
>>> square = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
>>> points, faces = triangulate_polygon(square, 0.25)
>>> bool(np.allclose(points[:4], square)), bool(abs(triangle_areas(points, faces).sum() - 1) < 1e-9)
(True, True)
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from fourd.errors import InputError

__all__ = ["resample_polyline", "signed_area", "triangle_areas", "triangulate_polygon"]


def signed_area(polygon: np.ndarray) -> float:
    """Area of a closed polygon ``[K, 2]``: positive when counter-clockwise."""
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def triangle_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed areas ``[F]`` of plane triangles (positive counter-clockwise)."""
    u = points[faces[:, 1]] - points[faces[:, 0]]
    v = points[faces[:, 2]] - points[faces[:, 0]]
    return 0.5 * (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])


def resample_polyline(points: np.ndarray, step: float, *, closed: bool = False, least: int = 2) -> np.ndarray:
    """Points ``[M, 2]`` at most ``step`` apart by arc length along ``points [K, 2]`` (back to
    the first point when ``closed``), its ends included, at least ``least`` of them."""
    path = np.vstack([points, points[:1]]) if closed else np.asarray(points, dtype=np.float64)
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    at = np.linspace(0.0, length[-1], max(least, int(np.ceil(length[-1] / step)) + 1))
    return np.column_stack([np.interp(at, length, path[:, k]) for k in range(path.shape[1])])


def triangulate_polygon(polygon: np.ndarray, edge: float) -> tuple[np.ndarray, np.ndarray]:
    """``(points [P, 2], faces [F, 3])`` covering the counter-clockwise ``polygon [K, 2]``
    (its points are ``points[:K]``); faces counter-clockwise."""
    from matplotlib.path import Path

    polygon = np.asarray(polygon, dtype=np.float64)
    count = len(polygon)
    if count < 3 or signed_area(polygon) <= 0:
        raise InputError("a polygon to triangulate needs 3 or more points, counter-clockwise")
    lower, upper = polygon.min(axis=0), polygon.max(axis=0)
    rows = np.arange(lower[1] + 0.5 * edge, upper[1], edge * np.sqrt(3) / 2)
    columns = np.arange(lower[0] + 0.5 * edge, upper[0], edge)
    x = columns[None, :] + (np.arange(len(rows)) % 2 * edge / 2)[:, None]
    lattice = np.column_stack([x.ravel(), np.broadcast_to(rows[:, None], x.shape).ravel()])
    path = Path(polygon)
    if len(lattice):
        inside = path.contains_points(lattice)
        far = cKDTree(resample_polyline(polygon, edge / 8, closed=True, least=8)).query(lattice)[0] > 0.6 * edge
        lattice = lattice[inside & far]
    points = np.concatenate([polygon, lattice])
    if len(points) >= 4:
        faces = Delaunay(points).simplices.astype(np.int64)
        faces = faces[path.contains_points(points[faces].mean(axis=1))]
        flipped = triangle_areas(points, faces) < 0
        faces[flipped] = faces[flipped][:, [0, 2, 1]]
        faces = faces[np.abs(triangle_areas(points, faces)) > 1e-14 * max(edge, 1e-12) ** 2]
        if _follows_outline(faces, count):
            return points, faces
    return polygon.copy(), _ear_clipping(polygon)


def _follows_outline(faces: np.ndarray, count: int) -> bool:
    """Whether every outline edge ``(k, k + 1)`` is the side of exactly one face, in that
    direction, and no other side is used by more than two faces."""
    sides = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    keys = sides[:, 0] * (faces.max() + 1) + sides[:, 1]
    outline = np.column_stack([np.arange(count), (np.arange(count) + 1) % count])
    wanted = outline[:, 0] * (faces.max() + 1) + outline[:, 1]
    present = np.isin(wanted, keys)
    undirected = np.sort(sides, axis=1)
    _, uses = np.unique(undirected[:, 0] * (faces.max() + 1) + undirected[:, 1], return_counts=True)
    return bool(present.all() and uses.max() <= 2)


def _ear_clipping(polygon: np.ndarray) -> np.ndarray:
    """Faces ``[K - 2, 3]`` of a simple counter-clockwise polygon by ear clipping."""
    remaining = list(range(len(polygon)))
    faces = []
    guard = 0
    while len(remaining) > 3 and guard < 10 * len(polygon) ** 2:
        guard += 1
        n = len(remaining)
        for k in range(n):
            a, b, c = remaining[(k - 1) % n], remaining[k], remaining[(k + 1) % n]
            triangle = polygon[[a, b, c]]
            if signed_area(triangle) <= 0:
                continue
            others = [v for v in remaining if v not in (a, b, c)]
            if others and _inside(triangle, polygon[others]).any():
                continue
            faces.append([a, b, c])
            remaining.pop(k)
            break
        else:  # no ear (a degenerate polygon): fan the rest
            break
    for k in range(1, len(remaining) - 1):
        faces.append([remaining[0], remaining[k], remaining[k + 1]])
    return np.asarray(faces, dtype=np.int64)


def _inside(triangle: np.ndarray, points: np.ndarray) -> np.ndarray:
    a, b, c = triangle
    def side(p, q, r):
        return (q[0] - p[0]) * (r[:, 1] - p[1]) - (q[1] - p[1]) * (r[:, 0] - p[0])
    return (side(a, b, points) > 0) & (side(b, c, points) > 0) & (side(c, a, points) > 0)
