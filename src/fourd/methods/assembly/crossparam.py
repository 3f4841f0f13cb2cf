"""Local patch-based cross-parameterisation of a source mesh onto a target mesh (thesis
section 5.4.2).

Every matching patch pair (:mod:`~fourd.methods.assembly.patches`) is flattened on both sides
(ABF++ by default, :mod:`fourd.geometry.flattening`); the source flattening is laid onto the
target's by the affine map that best aligns their anchors (least squares), and every source
vertex outside the patch's boundary band is located in the target flattening: a target
triangle and barycentric coordinates, i.e. a point on the target surface. A vertex in several
patches takes the map of the patch it lies most centrally in (smallest geodesic distance from
the centre relative to the radius: the alignment is best near the anchors, "Patch Selection").
Vertices no patch maps have no counterpart on the target (holes, or too few anchors near them).

The local relaxation that removes the flips where neighbouring vertices took different patches
(section 5.4.3) comes next; this is the initial map it starts from.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numba
import numpy as np

from fourd.geometry.flattening import flatten
from fourd.geometry.meshes import mesh_arrays
from fourd.methods.assembly.anchors import Anchors
from fourd.methods.assembly.options import CrossParamOptions
from fourd.methods.assembly.patches import PatchPair, grow_patches

log = logging.getLogger("fourd.methods.assembly.crossparam")

#: A point counts as inside a triangle down to this barycentric coordinate (rounding).
INSIDE = -1e-9


class CrossParameterization(NamedTuple):
    """A map from the source mesh's vertices to points on the target surface.

    faces : int64 [N]
        Target triangle of each source vertex; -1 where the vertex has no counterpart.
    barycentric : float64 [N, 3]
        Barycentric coordinates in that triangle (0 where unmapped).
    points : float64 [N, 3]
        The mapped points on the target (NaN where unmapped).
    patch : int64 [N]
        The patch pair whose map each vertex took (-1 where unmapped).
    patches : int
        Patch pairs whose map was used for some vertex or not (kept after growth and
        alignment).
    discarded : int
        Patch pairs given up: too few anchors within the largest radius, not disks, or anchors
        that fix no orientation-keeping affine map or do not align.
    """

    faces: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray
    patch: np.ndarray
    patches: int
    discarded: int

    @property
    def mapped(self) -> np.ndarray:
        """Whether each source vertex has a point on the target, bool [N]."""
        return self.faces >= 0


class PatchMap(NamedTuple):
    """One patch pair's map of its source vertices (:func:`map_patch`).

    vertices : int64 [K]
        Source vertices mapped (those outside the boundary band that fall inside the target
        flattening).
    faces : int64 [K]
        Target triangles.
    barycentric : float64 [K, 3]
    centrality : float64 [K]
        Geodesic distance from the patch's centre over its radius (0 at the centre).
    residual : float
        RMS distance, in the target flattening, of the aligned source anchors from the target
        anchors (input units).
    """

    vertices: np.ndarray
    faces: np.ndarray
    barycentric: np.ndarray
    centrality: np.ndarray
    residual: float


def _flat(vertices: np.ndarray, faces: np.ndarray, patch, method: str):
    """The patch's own mesh (local faces) and its flattening ``[M, 2]``."""
    local = np.searchsorted(patch.vertices, faces[patch.faces])
    return local, flatten(vertices[patch.vertices], local, method=method).uv


def _locate(uv: np.ndarray, faces: np.ndarray, points: np.ndarray):
    """The triangle of ``faces`` over ``uv`` holding each of ``points [P, 2]`` and the
    barycentric coordinates there; ``-1`` for points inside no triangle. Where the layout
    overlaps itself, the triangle a point lies deepest in (largest smallest coordinate)."""
    return _locate_kernel(np.ascontiguousarray(uv, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64),
                          np.ascontiguousarray(points, dtype=np.float64), INSIDE)


@numba.njit(cache=True, nogil=True)
def _locate_kernel(uv, faces, points, inside):
    """:func:`_locate` by a search over every triangle (a patch holds a few hundred)."""
    count = len(points)
    triangle = np.full(count, -1, dtype=np.int64)
    bary = np.zeros((count, 3))
    for p in range(count):
        px, py = points[p, 0], points[p, 1]
        best, best_v, best_w, best_f = -np.inf, 0.0, 0.0, -1
        for f in range(len(faces)):
            ax, ay = uv[faces[f, 0], 0], uv[faces[f, 0], 1]
            e1x, e1y = uv[faces[f, 1], 0] - ax, uv[faces[f, 1], 1] - ay
            e2x, e2y = uv[faces[f, 2], 0] - ax, uv[faces[f, 2], 1] - ay
            det = e1x * e2y - e1y * e2x
            if det == 0.0:
                continue
            rx, ry = px - ax, py - ay
            v = (rx * e2y - ry * e2x) / det
            w = (e1x * ry - e1y * rx) / det
            worst = min(1.0 - v - w, v, w)
            if worst > best:
                best, best_v, best_w, best_f = worst, v, w, f
        if best_f < 0 or not best >= inside:
            continue
        a, b, c = max(1.0 - best_v - best_w, 0.0), max(best_v, 0.0), max(best_w, 0.0)
        total = a + b + c
        triangle[p] = best_f
        bary[p, 0], bary[p, 1], bary[p, 2] = a / total, b / total, c / total
    return triangle, bary


def map_patch(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    anchors: Anchors,
    pair: PatchPair,
    options: CrossParamOptions | None = None,
) -> PatchMap | None:
    """Cross-parameterise one patch pair: flatten both patches, align the source flattening
    to the target's by the least-squares affine map of their anchors, locate the source
    vertices outside the boundary band in the target flattening.

    Returns
    -------
    PatchMap or None
        None when a patch has no finite flattening (degenerate triangles), or the anchors fix
        no orientation-keeping affine map (collinear anchors, or a mirror image), or their
        aligned positions stay more than ``max_residual`` of the radius apart: the patches do
        not match.
    """
    options = CrossParamOptions() if options is None else options
    source_local, source_uv = _flat(source_vertices, source_faces, pair.source, options.flattening)
    target_local, target_uv = _flat(target_vertices, target_faces, pair.target, options.flattening)
    if not (np.isfinite(source_uv).all() and np.isfinite(target_uv).all()):
        return None  # a degenerate patch (its layout's system singular): no map from it
    anchor_source = source_uv[np.searchsorted(pair.source.vertices, anchors.source[pair.anchors])]
    support = anchors.subset(pair.anchors).target_corners(target_faces)
    corner = np.searchsorted(pair.target.vertices, np.maximum(support, 0))
    weight = np.where(support >= 0, anchors.target_barycentric[pair.anchors], 0.0)
    anchor_target = np.einsum("ak,akd->ad", weight, target_uv[np.minimum(corner, len(target_uv) - 1)])
    design = np.concatenate([anchor_source, np.ones((len(anchor_source), 1))], axis=1)
    affine, _, rank, _ = np.linalg.lstsq(design, anchor_target, rcond=None)
    if rank < 3 or np.linalg.det(affine[:2]) <= 0:
        return None
    residual = float(np.sqrt(np.mean(np.sum((design @ affine - anchor_target) ** 2, axis=1))))
    if residual > options.max_residual * pair.source.radius:
        return None
    centrality = pair.source.distance / pair.source.radius
    inner = np.flatnonzero(centrality <= 1.0 - options.boundary_band)
    aligned = np.concatenate([source_uv[inner], np.ones((len(inner), 1))], axis=1) @ affine
    triangle, bary = _locate(target_uv, target_local, aligned)
    found = triangle >= 0
    return PatchMap(
        pair.source.vertices[inner[found]],
        pair.target.faces[triangle[found]],
        bary[found],
        centrality[inner[found]],
        residual,
    )


def cross_parameterize(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    anchors: Anchors,
    options: CrossParamOptions | None = None,
) -> CrossParameterization:
    """Map the source mesh's vertices onto the target surface by local patch
    cross-parameterisation (thesis section 5.4.2; module docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    target_vertices : array [M, 3]
    target_faces : int array [G, 3]
        Both meshes consistently oriented the same way (outward normals).
    anchors : Anchors
        Source vertices with their points on the target (thesis: about 3% of the vertices).
    options : CrossParamOptions, optional

    Returns
    -------
    CrossParameterization
    """
    options = CrossParamOptions() if options is None else options
    source_vertices, source_faces = mesh_arrays(source_vertices, source_faces)
    target_vertices, target_faces = mesh_arrays(target_vertices, target_faces)
    if len(anchors.source) < options.min_anchors:
        raise ValueError(f"a cross-parameterisation needs at least {options.min_anchors} anchors, "
                         f"got {len(anchors.source)}")
    grown = grow_patches(source_vertices, source_faces, target_vertices, target_faces, anchors, options)
    count = len(source_vertices)
    faces = np.full(count, -1, dtype=np.int64)
    bary = np.zeros((count, 3))
    patch = np.full(count, -1, dtype=np.int64)
    best = np.full(count, np.inf)
    kept, discarded = 0, grown.discarded
    for index, pair in enumerate(grown.pairs):
        mapped = map_patch(source_vertices, source_faces, target_vertices, target_faces, anchors, pair, options)
        if mapped is None:
            discarded += 1
            continue
        kept += 1
        better = mapped.centrality < best[mapped.vertices]
        chosen = mapped.vertices[better]
        faces[chosen] = mapped.faces[better]
        bary[chosen] = mapped.barycentric[better]
        best[chosen] = mapped.centrality[better]
        patch[chosen] = index
    points = np.full((count, 3), np.nan)
    ok = faces >= 0
    points[ok] = np.einsum("nk,nkd->nd", bary[ok], target_vertices[target_faces[faces[ok]]])
    log.debug("cross-parameterisation: %d patches, %d discarded, %.1f%% of the vertices mapped",
              kept, discarded, 100.0 * ok.mean())
    return CrossParameterization(faces, bary, points, patch, kept, discarded)
