"""Folds of a mesh, and how many of the truth's folds a result has (issue 54's wrinkle target).

One detector, used on the truth and on the result alike:

1. the surface's *fold height* at each vertex: its distance, along the normal, from the surface
   low-passed at ``wavelength`` (:mod:`fourd.geometry.low_pass`: a fold narrower than the
   cutoff stands out of it by most of its depth, a tube or a cone does not);
2. a *fold*: a connected set of vertices whose fold height exceeds half of ``depth`` with one
   sign (a ridge, positive along the normal, or a valley) and that reaches ``depth`` somewhere
   (hysteresis, as Canny's: a crest that dips under the threshold stays one fold), boundary
   vertices excluded (an open edge rolls out of any smoothed surface); its *crest* is its
   deepest vertex;
3. a truth fold is *found* when a result fold of the same sign has a vertex within
   ``distance`` of its crest, in the same frame.

Defaults are fractions of the truth's bounding-box diagonal: folds narrower than a tenth of the
diagonal (a wrinkle, not the garment's shape), deeper than 0.5%, found within 1% (the issue's
figures). A fold's height is what the filter leaves of it: a sinusoidal fold at half the cutoff
wavelength reads 94% of its amplitude, at the cutoff 50%.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fourd.geometry.boundary_loops import boundary_edges
from fourd.geometry.low_pass import low_pass_surface
from fourd.geometry.meshes import vertex_adjacency
from fourd.geometry.normals import vertex_normals

__all__ = ["FOLD_DEPTH", "FOLD_DISTANCE", "FOLD_WAVELENGTH", "Fold", "find_folds", "fold_heights", "fold_recall"]

#: Folds are narrower than this fraction of the diagonal (the low-pass cutoff wavelength).
FOLD_WAVELENGTH = 0.10
#: Folds deeper than this fraction of the diagonal count (the issue: 0.5%).
FOLD_DEPTH = 0.005
#: A truth fold is found by a result fold within this fraction of the diagonal (the issue: 1%).
FOLD_DISTANCE = 0.01


@dataclass(frozen=True)
class Fold:
    """One fold: ``vertices`` (indices), ``crest`` [3] (the deepest vertex's position),
    ``height`` (signed fold height at the crest, input units: positive a ridge)."""

    vertices: np.ndarray
    crest: np.ndarray
    height: float


def fold_heights(vertices: np.ndarray, faces: np.ndarray, wavelength: float) -> np.ndarray:
    """Fold height [N] (input units) of each vertex: its signed distance along the smoothed
    surface's normal from the surface low-passed at ``wavelength`` (input units;
    :func:`fourd.geometry.low_pass.low_pass_surface`). Vertices without a face get 0."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    base = low_pass_surface(vertices, faces, wavelength)
    heights = np.einsum("ij,ij->i", vertices - base, vertex_normals(base, faces))
    heights[np.bincount(faces.ravel(), minlength=len(vertices)) == 0] = 0.0
    return heights


def find_folds(vertices: np.ndarray, faces: np.ndarray, *, wavelength: float, depth: float) -> list[Fold]:
    """The folds of one mesh (module docstring): ``wavelength`` and ``depth`` in input units."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return []
    heights = fold_heights(vertices, faces, wavelength)
    edges = boundary_edges(faces, len(vertices))
    interior = np.ones(len(vertices), dtype=bool)
    interior[edges.ravel()] = False
    adjacency = vertex_adjacency(faces, len(vertices)).tocoo()
    folds = []
    for sign in (1.0, -1.0):
        deep = interior & (sign * heights > depth / 2)
        if not (deep & (sign * heights > depth)).any():
            continue
        keep = deep[adjacency.row] & deep[adjacency.col]
        graph = sp.csr_matrix(
            (np.ones(keep.sum()), (adjacency.row[keep], adjacency.col[keep])), shape=adjacency.shape
        )
        _, labels = connected_components(graph, directed=False)
        members = np.flatnonzero(deep)
        order = np.argsort(labels[members], kind="stable")
        members = members[order]
        starts = np.flatnonzero(np.r_[True, np.diff(labels[members]) != 0])
        for group in np.split(members, starts[1:]):
            crest = group[np.argmax(sign * heights[group])]
            if sign * heights[crest] <= depth:
                continue
            folds.append(Fold(group, vertices[crest].copy(), float(heights[crest])))
    return folds


def fold_recall(
    result,
    truth,
    *,
    wavelength: float = FOLD_WAVELENGTH,
    depth: float = FOLD_DEPTH,
    distance: float = FOLD_DISTANCE,
) -> dict:
    """How many of the truth's folds the result has, over every frame.

    ``result`` and ``truth``: anything with ``frame_count``, ``frame(t) -> (vertices, faces)``
    and ``diagonal()`` (an :class:`~fourd.animation.AnimatedMesh` or a
    :class:`~fourd.sequence.MeshSequence`). The fractions are of the truth's diagonal.

    Returns ``{"fold_recall": found / truth folds (None without truth folds), "folds_truth",
    "folds_result", "fold_precision": result folds near a truth fold of their sign / result
    folds (None without result folds), "per_frame_folds_truth", "per_frame_folds_found"}``.
    """
    diagonal = truth.diagonal()
    wavelength, depth, distance = wavelength * diagonal, depth * diagonal, distance * diagonal
    found_total, truth_total, result_total, near_total = 0, 0, 0, 0
    per_truth, per_found = [], []
    for t in range(truth.frame_count):
        tv, tf = truth.frame(t)
        rv, rf = result.frame(t)
        truth_folds = find_folds(tv, tf, wavelength=wavelength, depth=depth)
        result_folds = find_folds(rv, rf, wavelength=wavelength, depth=depth) if len(rf) else []
        if result_folds and _opposite_orientation(rv, rf, tv, tf):
            result_folds = [Fold(f.vertices, f.crest, -f.height) for f in result_folds]
        found = sum(_near(f.crest, f.height, result_folds, rv, distance) for f in truth_folds)
        near = sum(_near(f.crest, f.height, truth_folds, tv, distance) for f in result_folds)
        found_total += found
        near_total += near
        truth_total += len(truth_folds)
        result_total += len(result_folds)
        per_truth.append(len(truth_folds))
        per_found.append(int(found))
    return {
        "fold_recall": found_total / truth_total if truth_total else None,
        "fold_precision": near_total / result_total if result_total else None,
        "folds_truth": truth_total,
        "folds_result": result_total,
        "per_frame_folds_truth": per_truth,
        "per_frame_folds_found": per_found,
    }


def _near(crest: np.ndarray, height: float, folds: list[Fold], vertices: np.ndarray, distance: float) -> bool:
    """Whether a fold of ``height``'s sign among ``folds`` (over ``vertices``) has a vertex
    within ``distance`` of ``crest``."""
    for fold in folds:
        if np.sign(fold.height) != np.sign(height):
            continue
        if np.min(np.linalg.norm(vertices[fold.vertices] - crest, axis=1)) <= distance:
            return True
    return False


def _opposite_orientation(rv, rf, tv, tf) -> bool:
    """Whether the result's normals point the other way from the truth's (an open mesh's winding
    is arbitrary): the sign of the mean dot product at nearest vertices."""
    result_normals = vertex_normals(np.asarray(rv, float), np.asarray(rf, np.int64))
    truth_normals = vertex_normals(np.asarray(tv, float), np.asarray(tf, np.int64))
    nearest = cKDTree(tv).query(rv)[1]
    return float(np.einsum("ij,ij->", result_normals, truth_normals[nearest])) < 0
