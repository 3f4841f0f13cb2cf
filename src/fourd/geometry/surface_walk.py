"""Walking points along a triangle mesh: a displacement traced across faces, unfolded over
each crossed edge (a straightest path, Polthier and Schmies 1998), batched over many points.

A point on the surface is a face and barycentric coordinates in it. The walk moves it by a
tangent displacement: inside its face in a straight line; at an edge it continues into the
neighbouring face with the rest of the displacement rotated about the edge onto that face's
plane, so its length and its angle with the edge are kept. At a boundary edge (or a
non-manifold one) the walk stops on the edge.

References
----------
K. Polthier, M. Schmies, "Straightest geodesics on polyhedral surfaces", Mathematical
Visualization, 1998 (section 4: tracing a straightest path through edges).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from fourd.geometry.meshes import face_adjacency

#: A displacement shorter than this fraction of its face's first edge does not move.
TINY_STEP = 1e-10


class Walked(NamedTuple):
    """Where :func:`walk_on_surface` took the points.

    faces : int64 [K]
        The face each point ended in.
    barycentric : float64 [K, 3]
        Its coordinates there (non-negative, summing to 1).
    points : float64 [K, 3]
        The points.
    stopped : bool [K]
        Points stopped short: at a boundary edge, on a degenerate face, or out of crossings.
    """

    faces: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray
    stopped: np.ndarray


def face_neighbours(faces: np.ndarray) -> np.ndarray:
    """The face across each face's edges, int64 ``[F, 3]``: column ``k`` is the neighbour
    across the edge opposite corner ``k``; -1 on a boundary edge (and on a non-manifold edge,
    where no single neighbour exists).

    Examples
    --------
    >>> face_neighbours(np.array([[0, 1, 2], [2, 1, 3]])).tolist()
    [[1, -1, -1], [-1, -1, 0]]
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    pairs, edges = face_adjacency(faces)
    keys = edges[:, 0] * np.int64(faces.max(initial=0) + 1) + edges[:, 1]
    _, which, count = np.unique(keys, return_inverse=True, return_counts=True)
    single = count[which] == 1  # an edge of three or more faces comes in several pairs
    pairs, edges = pairs[single], edges[single]
    neighbours = np.full((len(faces), 3), -1, dtype=np.int64)
    for side, other in ((0, 1), (1, 0)):
        face = pairs[:, side]
        corners = faces[face]
        opposite = np.argmax((corners != edges[:, [0]]) & (corners != edges[:, [1]]), axis=1)
        neighbours[face, opposite] = pairs[:, other]
    return neighbours


def face_unit_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals of the faces ``[F, 3]`` (counter-clockwise corners; zero on a degenerate
    face)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    return np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)


def plane_barycentric(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``[K, 3]`` of ``points [K, 3]`` projected onto the planes of
    the triangles ``corners [K, 3, 3]`` (NaN on a degenerate triangle)."""
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    rel = points - corners[:, 0]
    d11 = np.einsum("kd,kd->k", e1, e1)
    d12 = np.einsum("kd,kd->k", e1, e2)
    d22 = np.einsum("kd,kd->k", e2, e2)
    r1 = np.einsum("kd,kd->k", rel, e1)
    r2 = np.einsum("kd,kd->k", rel, e2)
    det = d11 * d22 - d12 * d12
    with np.errstate(divide="ignore", invalid="ignore"):
        det = np.where(det > 1e-14 * np.maximum(d11 * d22, 1e-300), det, np.nan)
        v = (d22 * r1 - d12 * r2) / det
        w = (d11 * r2 - d12 * r1) / det
    return np.stack([1.0 - v - w, v, w], axis=1)


def walk_on_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    start_faces: np.ndarray,
    start_barycentric: np.ndarray,
    displacement: np.ndarray,
    *,
    neighbours: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    max_crossings: int = 64,
) -> Walked:
    """Move points on a mesh by tangent displacements, across edges (module docstring).

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
    start_faces : int array [K]
        The face each point starts in.
    start_barycentric : array [K, 3]
        Its coordinates there.
    displacement : array [K, 3]
        Input units; the part along the start face's normal is dropped.
    neighbours : int array [F, 3], optional
        :func:`face_neighbours` of ``faces`` (computed when not given).
    normals : array [F, 3], optional
        :func:`face_unit_normals` of the mesh (computed when not given).
    max_crossings : int
        Edges a point may cross; one still under way after that stops where it is.

    Returns
    -------
    Walked
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    neighbours = face_neighbours(faces) if neighbours is None else np.asarray(neighbours, dtype=np.int64)
    face = np.array(start_faces, dtype=np.int64).reshape(-1)
    bary = np.clip(np.array(start_barycentric, dtype=np.float64).reshape(-1, 3), 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    normal = face_unit_normals(vertices, faces) if normals is None else np.asarray(normals, dtype=np.float64)
    step = np.array(displacement, dtype=np.float64).reshape(-1, 3)
    stopped = _walk(vertices, faces, neighbours, normal, face, bary, step, int(max_crossings), TINY_STEP)
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    points = np.einsum("kc,kcd->kd", bary, vertices[faces[face]])
    return Walked(face, bary, points, stopped)


@numba.njit(cache=True, nogil=True)
def _walk(vertices, faces, neighbours, normals, face, bary, step, max_crossings, tiny):
    """Each point's walk (module docstring), one face at a time: ``face`` and ``bary`` are
    updated in place; returns which points stopped short."""
    stopped = np.zeros(len(face), dtype=np.bool_)
    for p in range(len(face)):
        face[p], stopped[p] = walk_point(vertices, faces, neighbours, normals, face[p], bary[p],
                                         step[p, 0], step[p, 1], step[p, 2], max_crossings, tiny)
    return stopped


@numba.njit(cache=True, nogil=True)
def walk_point(vertices, faces, neighbours, normals, f, bary, sx, sy, sz, max_crossings, tiny):
    """One point's walk from face ``f`` by the step ``(sx, sy, sz)`` (module docstring), for
    compiled callers: ``bary [3]`` is updated in place; returns the end face and whether the
    point stopped short."""
    along = sx * normals[f, 0] + sy * normals[f, 1] + sz * normals[f, 2]
    sx, sy, sz = sx - along * normals[f, 0], sy - along * normals[f, 1], sz - along * normals[f, 2]
    if not sx * sx + sy * sy + sz * sz > 0:
        return f, False
    for crossing in range(max_crossings + 2):
        if crossing == max_crossings + 1:
            return f, True
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        e1x, e1y, e1z = vertices[i1, 0] - vertices[i0, 0], vertices[i1, 1] - vertices[i0, 1], vertices[i1, 2] - vertices[i0, 2]
        e2x, e2y, e2z = vertices[i2, 0] - vertices[i0, 0], vertices[i2, 1] - vertices[i0, 1], vertices[i2, 2] - vertices[i0, 2]
        # what is left of a step at the rounding level of the face's size is no step (its
        # barycentric change is all noise, which would spin the point round a vertex)
        if not sx * sx + sy * sy + sz * sz > tiny * tiny * (e1x * e1x + e1y * e1y + e1z * e1z):
            return f, False
        h0, h1, h2 = bary[0], bary[1], bary[2]
        # the point moved, in the plane of the face, as barycentric coordinates
        rx = h1 * e1x + h2 * e2x + sx
        ry = h1 * e1y + h2 * e2y + sy
        rz = h1 * e1z + h2 * e2z + sz
        d11 = e1x * e1x + e1y * e1y + e1z * e1z
        d12 = e1x * e2x + e1y * e2y + e1z * e2z
        d22 = e2x * e2x + e2y * e2y + e2z * e2z
        r1 = rx * e1x + ry * e1y + rz * e1z
        r2 = rx * e2x + ry * e2y + rz * e2z
        det = d11 * d22 - d12 * d12
        if not det > 1e-14 * max(d11 * d22, 1e-300):
            return f, True
        t1 = (d22 * r1 - d12 * r2) / det
        t2 = (d11 * r2 - d12 * r1) / det
        t0 = 1.0 - t1 - t2
        c0, c1, c2 = t0 - h0, t1 - h1, t2 - h2
        corner = 0
        t = np.inf
        if c0 < 0:
            t, corner = max(h0, 0.0) / -c0, 0
        if c1 < 0 and max(h1, 0.0) / -c1 < t:
            t, corner = max(h1, 0.0) / -c1, 1
        if c2 < 0 and max(h2, 0.0) / -c2 < t:
            t, corner = max(h2, 0.0) / -c2, 2
        if t >= 1.0:
            bary[0], bary[1], bary[2] = t0, t1, t2
            return f, False
        b0 = 0.0 if corner == 0 else max(h0 + t * c0, 0.0)
        b1 = 0.0 if corner == 1 else max(h1 + t * c1, 0.0)
        b2 = 0.0 if corner == 2 else max(h2 + t * c2, 0.0)
        total = b0 + b1 + b2
        if not total > 0:  # a degenerate face
            return f, True
        bary[0], bary[1], bary[2] = b0 / total, b1 / total, b2 / total
        new = neighbours[f, corner]
        if new < 0:
            return f, True
        # the rest of the step, unfolded about the crossed edge onto the next face
        a, b = faces[f, (corner + 1) % 3], faces[f, (corner + 2) % 3]
        ax, ay, az = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
        length = np.sqrt(ax * ax + ay * ay + az * az)
        if not length > 0:  # a collapsed edge
            return f, True
        ax, ay, az = ax / length, ay / length, az / length
        rest = 1.0 - t
        sx, sy, sz = rest * sx, rest * sy, rest * sz
        ox, oy, oz = normals[f, 1] * az - normals[f, 2] * ay, normals[f, 2] * ax - normals[f, 0] * az, normals[f, 0] * ay - normals[f, 1] * ax
        nx, ny, nz = normals[new, 1] * az - normals[new, 2] * ay, normals[new, 2] * ax - normals[new, 0] * az, normals[new, 0] * ay - normals[new, 1] * ax
        forward = sx * ax + sy * ay + sz * az
        across = sx * ox + sy * oy + sz * oz
        sx, sy, sz = forward * ax + across * nx, forward * ay + across * ny, forward * az + across * nz
        weight_a, weight_b = bary[(corner + 1) % 3], bary[(corner + 2) % 3]
        for c in range(3):
            vertex = faces[new, c]
            bary[c] = weight_a if vertex == a else (weight_b if vertex == b else 0.0)
        f = new
    return f, True
