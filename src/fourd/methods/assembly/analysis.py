"""Analysis of a pair map against the gradual change assumption (thesis section 5.5).

Between consecutive frames the map from source to target should stretch triangles little and
move every vertex about as its neighbours move. Vertices of triangles whose edges the map
stretches or shrinks beyond ``stretch`` (a ratio), and vertices whose motion differs from
their one-ring's mean motion by more than ``motion`` source edges, are flagged; the flags are
grown by one ring, the small unflagged islands they enclose added (a region carried off whole
moves consistently inside, only its border breaks), and clustered into connected regions
(:func:`inconsistent_regions`).

The thesis then tries both fixes per region, the source's geometry pasted into the target and
the target's into the source, and keeps the one that passes a stretch test (overall stretch
within 0.9-1.1, at most 15% of the area outside), or deletes the region when neither does.
With one connectivity kept from the source (:mod:`~fourd.methods.assembly.hierarchy`), the
source's geometry pasted into the target is what the Laplacian registration does for unmapped
vertices; so the correction unmaps the flagged regions and lets the registration place them,
and :func:`passes_stretch_test` tells whether the result keeps the gradual change; a region
that fails is deleted and the target's geometry pasted in its place
(:mod:`~fourd.methods.assembly.completion`), tested the same way.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from fourd.geometry.meshes import face_areas, median_edge_length, mesh_arrays, vertex_adjacency


class Analysis(NamedTuple):
    """The result of :func:`inconsistent_regions`.

    flagged : bool [N]
        Vertices in an inconsistent region (grown by one ring).
    region : int64 [N]
        Region of each flagged vertex (-1 elsewhere).
    regions : int
        Number of regions.
    stretched : int
        Triangles flagged for stretch.
    moved : int
        Vertices flagged for motion.
    """

    flagged: np.ndarray
    region: np.ndarray
    regions: int
    stretched: int
    moved: int


def edge_ratios(source_vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Length of each triangle edge after the map over its length before, ``[F, 3]`` (NaN where
    a corner is unmapped)."""
    before = np.linalg.norm(source_vertices[faces[:, [1, 2, 0]]] - source_vertices[faces], axis=2)
    after = np.linalg.norm(points[faces[:, [1, 2, 0]]] - points[faces], axis=2)
    return after / np.maximum(before, 1e-300)


def inconsistent_regions(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    points: np.ndarray,
    mapped: np.ndarray,
    *,
    stretch: float = 2.0,
    motion: float = 1.5,
) -> Analysis:
    """Flag and cluster the vertices where the map breaks the gradual change (module
    docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    points : array [N, 3]
        The map's points on the target (rows of unmapped vertices ignored).
    mapped : bool array [N]
    stretch : float
        A triangle is stretched when an edge's length ratio leaves ``[1 / stretch, stretch]``.
    motion : float
        A vertex moves inconsistently when its motion differs from the mean motion of its
        mapped neighbours by more than this many source edges.

    Returns
    -------
    Analysis
    """
    vertices, faces = mesh_arrays(source_vertices, source_faces)
    count = len(vertices)
    mapped = np.asarray(mapped, dtype=bool)
    points = np.where(mapped[:, None], np.asarray(points, dtype=np.float64), np.nan)
    edge = median_edge_length(vertices, faces)
    ratios = edge_ratios(vertices, faces, points)
    full = mapped[faces].all(axis=1)
    bad_face = full & ((ratios > stretch) | (ratios < 1.0 / stretch)).any(axis=1)
    flagged = np.zeros(count, dtype=bool)
    flagged[faces[bad_face].ravel()] = True
    adjacency = vertex_adjacency(faces, count).tocsr()
    motion_vectors = np.where(mapped[:, None], points - vertices, 0.0)
    weights = adjacency @ sp.diags(mapped.astype(np.float64))
    neighbours = np.asarray(weights.sum(axis=1)).ravel()
    mean = (weights @ motion_vectors) / np.maximum(neighbours, 1.0)[:, None]
    deviation = np.linalg.norm(motion_vectors - mean, axis=1)
    moved = mapped & (neighbours > 0) & (deviation > motion * edge)
    flagged |= moved
    # one ring around, so a region covers the neighbourhood it disturbs
    flagged = flagged | ((adjacency @ flagged.astype(np.float64)) > 0)
    flagged = _fill_islands(adjacency, flagged) & mapped
    region = np.full(count, -1, dtype=np.int64)
    regions = 0
    if flagged.any():
        inside = sp.diags(flagged.astype(np.float64))
        _, label = connected_components(inside @ adjacency @ inside, directed=False)
        _, region_of = np.unique(label[flagged], return_inverse=True)
        region[flagged] = region_of
        regions = int(region_of.max()) + 1
    return Analysis(flagged, region, regions, int(bad_face.sum()), int(moved.sum()))


def _fill_islands(adjacency: sp.csr_matrix, flagged: np.ndarray) -> np.ndarray:
    """``flagged`` with the unflagged islands it encloses added: in each connected piece of
    the mesh, every unflagged component but the largest that has no more vertices than the
    piece's flagged ones (a small region carried off whole moves consistently inside; only its
    border stretches). A larger one is not an island: a band of flags across a neck that the
    next frame breaks cuts the piece in two halves, and either half added would take the neck's
    region with it through the stretch test (``test_a_bridge_the_next_frame_breaks_is_found_and_cut``)."""
    _, piece = connected_components(adjacency, directed=False)
    free = sp.diags((~flagged).astype(np.float64))
    _, label = connected_components(free @ adjacency @ free, directed=False)
    label = np.where(flagged, -1, label)
    result = flagged.copy()
    for p in np.unique(piece):
        members = (piece == p) & ~flagged
        if not members.any():
            continue
        labels, sizes = np.unique(label[members], return_counts=True)
        enclosed = labels[(labels != labels[np.argmax(sizes)]) & (sizes <= np.sum(flagged & (piece == p)))]
        result |= members & np.isin(label, enclosed)
    return result


def passes_stretch_test(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    points: np.ndarray,
    region: np.ndarray,
    *,
    overall: tuple[float, float] = (0.9, 1.1),
    outside: float = 0.15,
) -> bool:
    """The thesis' gradual change test of a replaced region (5.5): its triangles' overall
    stretch (the square root of their mapped area over their source area) within ``overall``,
    and at most ``outside`` of their source area stretched outside that range.

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    points : array [N, 3]
        The region's positions after the replacement (finite on its vertices).
    region : bool array [N]
        The region's vertices; its triangles are those with a corner in it.
    """
    vertices, faces = mesh_arrays(source_vertices, source_faces)
    touched = np.asarray(region, dtype=bool)[faces].any(axis=1)
    if not touched.any():
        return True
    before = face_areas(vertices, faces[touched])
    after = face_areas(np.nan_to_num(np.asarray(points, dtype=np.float64)), faces[touched])
    total = float(np.sqrt(after.sum() / max(before.sum(), 1e-300)))
    each = np.sqrt(after / np.maximum(before, 1e-300))
    off = before[(each < overall[0]) | (each > overall[1])].sum() / max(before.sum(), 1e-300)
    return bool(overall[0] <= total <= overall[1] and off <= outside)
