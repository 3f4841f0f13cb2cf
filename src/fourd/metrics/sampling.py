"""Dense surface samples and exact closest points on triangle meshes, vectorised.

The metrics in :mod:`fourd.metrics.scores` compare surfaces through seeded, area-weighted
samples (fast, with a small floor reported beside every figure) and bind vertices to the true
surface through exact closest points on candidate triangles found from those samples.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from fourd.geometry.closest_point import (
    closest_on_candidates,
    closest_on_triangles,  # noqa: F401 (re-exported: it was defined here)
)
from fourd.geometry.meshes import face_areas  # noqa: F401 (re-exported: metrics.sampling.face_areas)
from fourd.geometry.surface_samples import (  # noqa: F401 (re-exported: they were defined here)
    SurfaceSamples,
    sample_points,
    sample_surface,
)


class Binding(NamedTuple):
    """Points bound to a surface: triangle and barycentric coordinates (or point indices).

    Attributes
    ----------
    faces : ndarray int64 [M]
        Triangle of each bound point; ``-1`` when bound to a point set without faces (then the
        first column of ``barycentric`` holds the index of the bound point).
    barycentric : ndarray float64 [M, 3]
    distances : ndarray float64 [M]
        Distance from each query point to its bound surface point (input units).
    points : ndarray float64 [M, 3]
        The bound surface points.
    """

    faces: np.ndarray
    barycentric: np.ndarray
    distances: np.ndarray
    points: np.ndarray


def bind_to_surface(
    queries: np.ndarray,
    vertices: np.ndarray,
    faces: np.ndarray,
    samples: SurfaceSamples,
    *,
    candidates: int = 8,
) -> Binding:
    """Nearest surface point of every query, as triangle and barycentric coordinates.

    Candidate triangles are those of the ``candidates`` nearest dense samples and of the
    triangles around the nearest mesh vertex; the exact closest point is taken over them (for a
    densely sampled surface this is the true closest point up to sampling gaps). For a mesh
    without faces the nearest vertex is returned with ``faces = -1`` and barycentric ``[i, 0, 0]``
    holding the vertex index ``i``.
    """
    queries = np.asarray(queries, dtype=np.float64)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        distances, index = cKDTree(vertices).query(queries, workers=-1)
        bary = np.zeros((len(queries), 3))
        bary[:, 0] = index
        return Binding(np.full(len(queries), -1, dtype=np.int64), bary, distances, vertices[index])
    k = int(max(1, min(candidates, len(samples.points))))
    sample_tree, vertex_tree = cKDTree(samples.points), cKDTree(vertices)
    # A face around every vertex (covers points near sharp corners / sparse samples).
    vertex_face = np.zeros(len(vertices), dtype=np.int64)
    for corner in range(3):
        vertex_face[faces[:, corner]] = np.arange(len(faces))
    if len(queries) == 0:
        return Binding(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
    corners = vertices[faces]
    parts = [
        _bind_block(queries[start : start + _BLOCK], corners, samples, sample_tree, vertex_tree, vertex_face, k)
        for start in range(0, len(queries), _BLOCK)
    ]
    return Binding(*(np.concatenate([getattr(p, name) for p in parts]) for name in Binding._fields))


#: Queries bound per block (bounds the memory of the candidate tests to ~100 MB).
_BLOCK = 100_000


def _bind_block(queries, corners, samples, sample_tree, vertex_tree, vertex_face, k) -> Binding:
    _, near = sample_tree.query(queries, k=k, workers=-1)
    near = near.reshape(len(queries), k)
    _, nearest_vertex = vertex_tree.query(queries, workers=-1)
    candidate_faces = np.concatenate([samples.faces[near], vertex_face[nearest_vertex][:, None]], axis=1)
    found = closest_on_candidates(queries, corners, candidate_faces)
    return Binding(found.triangle, found.barycentric, found.distances, found.points)


def bound_positions(binding: Binding, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Positions of bound points on a mesh whose vertices move: ``vertices`` ``[N, 3]`` or
    ``[T, N, 3]`` -> ``[M, 3]`` or ``[T, M, 3]``."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0 or np.all(binding.faces < 0):
        index = binding.barycentric[:, 0].astype(np.int64)
        return vertices[..., index, :]
    tri = faces[binding.faces]  # [M, 3]
    corners = vertices[..., tri, :]  # [..., M, 3, 3]
    return np.einsum("mk,...mkd->...md", binding.barycentric, corners)
