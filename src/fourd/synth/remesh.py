"""Per-frame meshes with perfect geometry: a truth surface remeshed on its own.

Marching cubes of the truth's signed distance on a grid whose origin moves by a random
fraction of a cell every frame, then every vertex projected onto the truth triangles: the
vertices lie on the true surface (to rounding), and every frame has a triangulation of its
own. A method reconstructing from these meshes sees no noise, no holes and no outliers, so
its correspondence error measures the cross-parameterisation alone (issue 51; the input of
the thesis' chapter 5 is per-frame meshes).

The signed distance is computed exactly in a narrow band around the surface (closest points
on the truth triangles, signed by the angle-weighted pseudonormal of the closest feature,
Bærentzen and Aanæs 2005); marching cubes runs only in the cells whose corners all lie in the
band. On an open surface the zero set also runs on past the boundary (where the closest point
is on a boundary edge); the triangles there are dropped (their vertices lie off the surface),
so an open boundary is cut back by up to a cell.

References
----------
J. A. Bærentzen, H. Aanæs, "Signed distance computation using the angle weighted
pseudonormal", IEEE TVCG 11(3), 2005 (sections 3-4: the sign from the pseudonormal of the
closest face, edge or vertex).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fourd.errors import InputError
from fourd.geometry.grid import Grid, grid_points, vertices_near
from fourd.geometry.marching import compact, marching_cubes
from fourd.geometry.meshes import face_areas
from fourd.metrics.sampling import bind_to_surface, sample_surface

#: Band around the surface, in cells, where the signed distance is computed (a cell crossed
#: by the surface has every corner within sqrt(3) cells of it).
BAND_CELLS = 2.5
#: Vertices of the marching-cubes mesh farther than this (in cells) from the truth before the
#: projection lie on the zero set's continuation past an open boundary: their faces go.
OFF_SURFACE_CELLS = 0.25


class Remeshed(NamedTuple):
    """A truth surface remeshed (:func:`remesh_surface`).

    vertices : float64 [N, 3]
        On the truth surface: ``vertices[i]`` is the point of truth triangle
        ``truth_faces[i]`` at ``barycentric[i]``.
    faces : int64 [F, 3]
        Counter-clockwise seen from outside (the truth's orientation).
    truth_faces : int64 [N]
    barycentric : float64 [N, 3]
        Where each vertex lies on the truth: the true correspondence of the vertex in any
        other frame of an animated truth (same triangle, same coordinates).
    """

    vertices: np.ndarray
    faces: np.ndarray
    truth_faces: np.ndarray
    barycentric: np.ndarray


def _pseudonormals(vertices: np.ndarray, faces: np.ndarray):
    """Unit face normals [F, 3], angle-weighted vertex normals [N, 3] and the edge
    normals (sorted edge keys [E], normals [E, 3]) of a triangle mesh."""
    corners = vertices[faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face_normals /= np.maximum(np.linalg.norm(face_normals, axis=1, keepdims=True), 1e-300)
    angles = np.empty((len(faces), 3))
    for k in range(3):
        a = corners[:, (k + 1) % 3] - corners[:, k]
        b = corners[:, (k + 2) % 3] - corners[:, k]
        angles[:, k] = np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))
    vertex_normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(vertex_normals, faces[:, k], angles[:, k, None] * face_normals)
    edges = np.sort(faces[:, [1, 2, 2, 0, 0, 1]].reshape(-1, 2), axis=1)  # opposite corner k
    keys = edges[:, 0] * np.int64(len(vertices)) + edges[:, 1]
    unique, inverse = np.unique(keys, return_inverse=True)
    edge_normals = np.zeros((len(unique), 3))
    np.add.at(edge_normals, inverse.ravel(), np.repeat(face_normals, 3, axis=0))
    return face_normals, vertex_normals, unique, edge_normals


def _signed(queries, vertices, faces, binding, normals) -> np.ndarray:
    """The distances of ``binding`` signed by the pseudonormal of each closest feature."""
    face_normals, vertex_normals, edge_keys, edge_normals = normals
    bary, face = binding.barycentric, binding.faces
    zeros = (bary == 0.0).sum(axis=1)
    pseudo = face_normals[face].copy()
    at_vertex = zeros == 2
    pseudo[at_vertex] = vertex_normals[faces[face[at_vertex], np.argmax(bary[at_vertex], axis=1)]]
    at_edge = np.flatnonzero(zeros == 1)
    if len(at_edge):
        k = np.argmin(bary[at_edge], axis=1)  # the corner opposite the edge
        tri = faces[face[at_edge]]
        rows = np.arange(len(at_edge))
        a, b = tri[rows, (k + 1) % 3], tri[rows, (k + 2) % 3]
        keys = np.minimum(a, b) * np.int64(len(vertices)) + np.maximum(a, b)
        pseudo[at_edge] = edge_normals[np.searchsorted(edge_keys, keys)]
    side = np.einsum("ij,ij->i", queries - binding.points, pseudo)
    return np.where(side < 0, -binding.distances, binding.distances)


def remesh_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    spacing: float,
    offset: np.ndarray | None = None,
    seed: int = 0,
) -> Remeshed:
    """Remesh a triangle surface by marching cubes of its signed distance, with every vertex
    projected back onto it.

    Parameters
    ----------
    vertices : array [N, 3]
    faces : int array [F, 3]
        Consistently oriented (outward normals for a closed surface).
    spacing : float
        Grid cell edge (input units): about the new mesh's edge length.
    offset : array [3], optional
        Shift of the grid's origin in cells (each in [0, 1)); a different offset gives a
        different triangulation of the same surface. Default 0.
    seed : int
        Seed of the dense surface samples that find the candidate triangles of each closest
        point (the result is exact whichever samples are drawn, up to sampling gaps).

    Returns
    -------
    Remeshed

    Raises
    ------
    InputError
        No faces, a spacing that is not positive, or a surface too small for the grid (no
        triangle comes out).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise InputError("remeshing needs a surface with faces (a point truth has none)")
    if not (np.isfinite(spacing) and spacing > 0):
        raise InputError(f"spacing must be positive, got {spacing!r}")
    offset = np.zeros(3) if offset is None else np.asarray(offset, dtype=np.float64).reshape(3)
    h = float(spacing)
    lo, hi = vertices[faces].reshape(-1, 3).min(axis=0), vertices[faces].reshape(-1, 3).max(axis=0)
    origin = lo - (BAND_CELLS + 1.0 - offset) * h
    shape = np.ceil((hi + (BAND_CELLS + 1.0) * h - origin) / h).astype(np.int64) + 1
    grid = Grid(origin, h, tuple(int(n) for n in shape))
    # samples about a fifth of a cell apart find the closest triangle of a grid point (at a
    # third, bending-arm's elbow had marching-cubes vertices 0.3 cells off the surface)
    area = float(face_areas(vertices, faces).sum())
    count = int(min(max(25.0 * area / h**2, 10 * len(faces)), 4_000_000))
    samples = sample_surface(vertices, faces, count, np.random.default_rng(seed))
    band = vertices_near(grid, np.concatenate([samples.points[::4], vertices]), BAND_CELLS * h)
    queries = grid_points(grid, band)
    normals = _pseudonormals(vertices, faces)
    binding = bind_to_surface(queries, vertices, faces, samples)
    values = np.full(grid.size, np.nan)
    values[band] = _signed(queries, vertices, faces, binding, normals)
    values = values.reshape(grid.shape)
    known = np.isfinite(values)
    cells = known[:-1, :-1, :-1].copy()
    for di, dj, dk in np.ndindex(2, 2, 2):
        cells &= known[di : di + grid.shape[0] - 1, dj : dj + grid.shape[1] - 1, dk : dk + grid.shape[2] - 1]
    new_vertices, new_faces = marching_cubes(values, origin=grid.origin, spacing=h, cell_mask=cells)
    if len(new_faces) == 0:
        raise InputError(f"remeshing at spacing {h:.4g} left no triangles (the surface is too small)")
    binding = bind_to_surface(new_vertices, vertices, faces, samples)
    on_surface = binding.distances <= OFF_SURFACE_CELLS * h
    new_faces = new_faces[on_surface[new_faces].all(axis=1)]
    projected = binding.points
    # the projection can collapse a marching-cubes sliver onto a line
    new_faces = new_faces[face_areas(projected, new_faces) > 1e-10 * h * h]
    if len(new_faces) == 0:
        raise InputError(f"remeshing at spacing {h:.4g} left no triangles on the surface")
    used = np.unique(new_faces)
    kept, new_faces = compact(projected, new_faces)
    return Remeshed(kept, new_faces, binding.faces[used], binding.barycentric[used])
