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
    neighbours = face_neighbours(faces) if neighbours is None else np.asarray(neighbours)
    face = np.array(start_faces, dtype=np.int64).reshape(-1)
    bary = np.clip(np.array(start_barycentric, dtype=np.float64).reshape(-1, 3), 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    normal = face_unit_normals(vertices, faces) if normals is None else np.asarray(normals, dtype=np.float64)
    step = np.array(displacement, dtype=np.float64).reshape(-1, 3)
    step -= np.einsum("kd,kd->k", step, normal[face])[:, None] * normal[face]
    stopped = np.zeros(len(face), dtype=bool)
    active = np.flatnonzero(np.einsum("kd,kd->k", step, step) > 0)
    for _ in range(max_crossings + 1):
        if len(active) == 0:
            break
        f = face[active]
        corners = vertices[faces[f]]
        # what is left of a step at the rounding level of the face's size is no step (its
        # barycentric change is all noise, which would spin the point round a vertex)
        size = np.einsum("kd,kd->k", corners[:, 1] - corners[:, 0], corners[:, 1] - corners[:, 0])
        going = np.einsum("kd,kd->k", step[active], step[active]) > (TINY_STEP**2) * size
        active, f, corners = active[going], f[going], corners[going]
        here = bary[active]
        there = plane_barycentric(corners, np.einsum("kc,kcd->kd", here, corners) + step[active])
        bad = ~np.isfinite(there).all(axis=1)
        change = np.where(bad[:, None], 0.0, there - here)
        with np.errstate(divide="ignore", invalid="ignore"):
            exit_at = np.where(change < 0, np.maximum(here, 0.0) / -change, np.inf)
        corner = np.argmin(exit_at, axis=1)
        rows = np.arange(len(active))
        t = exit_at[rows, corner]
        inside = (t >= 1.0) & ~bad
        bary[active[inside]] = there[inside]
        stopped[active[bad]] = True
        leave = np.flatnonzero(~inside & ~bad)
        if len(leave) == 0:
            active = active[:0]
            break
        moving, k, t = active[leave], corner[leave], t[leave]
        edge_bary = here[leave] + t[:, None] * change[leave]
        edge_bary[np.arange(len(leave)), k] = 0.0
        edge_bary = np.clip(edge_bary, 0.0, None)
        edge_bary /= edge_bary.sum(axis=1, keepdims=True)
        bary[moving] = edge_bary
        rest = (1.0 - t)[:, None] * step[moving]
        old = face[moving]
        new = neighbours[old, k]
        border = new < 0
        stopped[moving[border]] = True
        cross = ~border
        moving, k, old, new, rest = moving[cross], k[cross], old[cross], new[cross], rest[cross]
        a = faces[old, (k + 1) % 3]
        b = faces[old, (k + 2) % 3]
        axis = vertices[b] - vertices[a]
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        along = np.einsum("kd,kd->k", rest, axis)[:, None]
        across = np.einsum("kd,kd->k", rest, np.cross(normal[old], axis))[:, None]
        step[moving] = along * axis + across * np.cross(normal[new], axis)
        weight_a = bary[moving, (k + 1) % 3]
        weight_b = bary[moving, (k + 2) % 3]
        target = faces[new]
        bary[moving] = (target == a[:, None]) * weight_a[:, None] + (target == b[:, None]) * weight_b[:, None]
        face[moving] = new
        active = moving
    else:
        stopped[active] = True
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    points = np.einsum("kc,kcd->kd", bary, vertices[faces[face]])
    return Walked(face, bary, points, stopped)
