"""Helpers over triangle meshes ``(vertices [N, 3], faces int [F, 3])``: enclosed volume,
vertex adjacency, connected components and the removal of small ones.

One home for what several methods, the synthetic scenes and the metrics need (each kept the
exact arithmetic of the copy it replaces, so results are bit-identical).
"""

from __future__ import annotations

import logging
from typing import Literal

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from fourd.geometry.marching import compact

log = logging.getLogger("fourd.geometry.meshes")


def _triple_products(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``a . (b x c)`` of every face's corners [F] (six times its signed volume)."""
    tri = vertices[faces]
    return np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))


def mesh_arrays(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices float64 [N, 3], faces int64 [F, 3])`` of any array-likes (no copy when they
    already are)."""
    return (
        np.asarray(vertices, dtype=np.float64).reshape(-1, 3),
        np.asarray(faces, dtype=np.int64).reshape(-1, 3),
    )


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas ``[F]`` (input units squared)."""
    a = vertices[faces[:, 0]]
    return 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - a, vertices[faces[:, 2]] - a), axis=1)


def face_volumes(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Each face's signed volume ``a . (b x c) / 6`` against the origin [F]: their sum over a
    closed mesh is the volume it encloses (positive for outward-oriented faces)."""
    return _triple_products(vertices, faces) / 6.0


def enclosed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed, consistently oriented mesh (absolute value; input units^3).

    The triple products are summed before the division by 6 (``face_volumes(...).sum()``
    divides first: the two may differ in the last bit)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    return float(abs(_triple_products(vertices, faces).sum() / 6.0))


def vertex_adjacency(faces: np.ndarray, count: int) -> sp.csr_matrix:
    """Symmetric 0/1 adjacency [count, count] of the vertices joined by an edge of ``faces``
    (canonical CSR: sorted indices, no duplicates)."""
    rows = faces[:, [0, 1, 2, 1, 2, 0]].ravel()
    cols = faces[:, [1, 2, 0, 0, 1, 2]].ravel()
    graph = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(count, count))
    graph.data[:] = 1.0
    return graph


def vertex_components(faces: np.ndarray, vertex_count: int) -> tuple[int, np.ndarray]:
    """Connected components of a mesh's vertices joined by the edges of ``faces`` [F, 3]:
    ``(count, labels [vertex_count])``; a vertex of no face is a component of its own."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    i = faces.ravel()
    j = np.roll(faces, 1, axis=1).ravel()
    graph = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(vertex_count, vertex_count))
    return connected_components(graph, directed=False)


def component_volumes(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """The closed components of a mesh: the component of every face [F] and the signed volume
    each encloses [C] (positive for outward-oriented faces, negative for a cavity's inner
    surface). Faces belong together when they share an edge that no other face has
    (:func:`face_pieces` with ``manifold_only``), so a piece that touches the rest only at
    vertices or along edges of three or more faces is a component of its own and can be
    dropped by its volume (marching cubes once left a flat doubled quad, four faces enclosing
    nothing, on two edges of a resolution-64 surface)."""
    _, face_label = face_pieces(faces, manifold_only=True)
    return face_label, np.bincount(face_label, weights=face_volumes(vertices, faces))


def remove_small_components(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    min_faces: int = 0,
    min_fraction: float = 0.0,
    measure: Literal["faces", "volume"] = "faces",
) -> tuple[np.ndarray, np.ndarray]:
    """The mesh without its small connected components, re-indexed (unchanged when nothing
    is dropped).

    Parameters
    ----------
    min_faces : int
        With ``measure="faces"``: drop the components (vertices joined by edges) with fewer
        faces than this (0 or 1: no limit).
    min_fraction : float
        Drop the components below this fraction of the largest (0: no limit): by face count
        with ``measure="faces"``; by the absolute enclosed volume of the closed components of
        :func:`component_volumes` with ``measure="volume"`` (a cavity's inner surface counts
        by its size).
    """
    if measure == "volume":
        if len(faces) == 0 or min_fraction <= 0:
            return vertices, faces
        face_label, volume = component_volumes(vertices, faces)
        if len(volume) <= 1:
            return vertices, faces
        volume = np.abs(volume)
        faces = faces[(volume >= min_fraction * volume.max())[face_label]]
        return compact(vertices, faces)
    if measure != "faces":
        raise ValueError(f"measure must be 'faces' or 'volume', got {measure!r}")
    if len(faces) == 0 or (min_faces <= 1 and min_fraction <= 0):
        return vertices, faces
    parts, labels = vertex_components(faces, len(vertices))
    face_label = labels[faces[:, 0]]
    sizes = np.bincount(face_label)
    large = (sizes >= min_faces) & (sizes >= min_fraction * sizes.max())
    keep = large[face_label]
    log.debug("components: %d, %d kept", parts, int(large.sum()))
    if keep.all():
        return vertices, faces
    return compact(vertices, faces[keep])


def median_edge_length(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Median length of the edges of ``faces`` [F, 3] over ``vertices`` [N, 3]."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    lengths = np.linalg.norm(vertices[faces[:, [1, 2, 0]]] - vertices[faces], axis=2)
    return float(np.median(lengths))


def face_adjacency(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of faces sharing an edge, and that edge.

    Returns ``(pairs, edges)``: int64 [E, 2] face indices (``pairs[:, 0] < pairs[:, 1]``) and
    int64 [E, 2] the shared edge's vertex indices (sorted), in a deterministic order (by
    edge). An edge with more than two faces (non-manifold) links its faces in consecutive
    pairs; a boundary edge links none.

    Examples
    --------
    >>> pairs, edges = face_adjacency(np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]]))
    >>> pairs.tolist(), edges.tolist()
    ([[0, 1]], [[0, 2]])
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(len(faces)), 3)
    # one key per side, sorted stably: by edge, then by face (owner is already ascending)
    span = np.int64(max(int(faces.max(initial=-1)) + 1, 1))
    order = np.argsort(edges[:, 0] * span + edges[:, 1], kind="stable")
    edges, owner = edges[order], owner[order]
    same = np.all(edges[1:] == edges[:-1], axis=1)
    first, second = owner[:-1][same], owner[1:][same]
    pairs = np.stack([np.minimum(first, second), np.maximum(first, second)], axis=1)
    return pairs, edges[:-1][same]


def face_pieces(faces: np.ndarray, *, manifold_only: bool = False) -> tuple[int, np.ndarray]:
    """Pieces of surface: faces joined by shared sides (:func:`face_adjacency`), so two pieces
    that only touch at a vertex are two; with ``manifold_only``, only by sides no third face
    has, so pieces meeting along a non-manifold edge are two as well. ``(count, labels [F])``,
    labels numbered in the order of each piece's first face."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    pairs, edges = face_adjacency(faces)
    if manifold_only and len(pairs):
        # an edge of k faces gives k - 1 consecutive pairs (face_adjacency sorts by edge)
        new_edge = np.r_[True, np.any(edges[1:] != edges[:-1], axis=1)]
        run = np.cumsum(new_edge) - 1
        pairs = pairs[np.bincount(run)[run] == 1]
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(faces),) * 2)
    count, labels = connected_components(graph, directed=False)
    return int(count), labels
