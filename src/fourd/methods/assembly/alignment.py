"""Anchors from geometry alone: a coarse non-rigid alignment of the source onto the target,
then closest points (the fallback of thesis section 5.4, "without any correspondences,
geometric proximity is the only way to initialize such a parameterization"; the thesis takes
its anchors from optical flow, 5.4.1, which scans without video do not have).

1. Rigid ICP: the source is moved by the trimmed point-to-plane ICP of
   :func:`fourd.geometry.icp.rigid_icp` (pairs whose normals disagree or that lie beyond the
   85th percentile of the gaps left out), from two starts.
2. Non-rigid ICP: a spread of control vertices jumps to its nearest target vertices and the
   rest follows by the source's Laplacian coordinates
   (:func:`~fourd.methods.assembly.registration.register_by_laplacian`), a few times.
3. Anchors: spread source vertices (about one per ``spacing`` source edges) whose aligned
   position lies within ``gap`` edges of the target, each matched to its closest target point
   on the triangles; then the forward-backward check of 5.4.1
   (:func:`~fourd.methods.assembly.anchors.consistent_anchors`), the backward map of a target
   vertex being the source position of the aligned source vertex nearest it, and a final
   :func:`~fourd.methods.assembly.anchors.spread_anchors`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from fourd.geometry.icp import rigid_icp as point_to_plane_icp
from fourd.geometry.meshes import median_edge_length, mesh_arrays
from fourd.geometry.normals import vertex_normals
from fourd.methods.assembly.anchors import (
    Anchors,
    consistent_anchors,
    returned_points,
    spread_anchors,
)
from fourd.methods.assembly.registration import register_by_laplacian


class Alignment(NamedTuple):
    """The result of :func:`geometric_anchors`.

    anchors : Anchors
    aligned : float64 [N, 3]
        The source vertices after the coarse non-rigid alignment (target's frame).
    edge : float
        The source's median edge length (input units).
    """

    anchors: Anchors
    aligned: np.ndarray
    edge: float


def _pairs(points, normals, tree, target_normals):
    """Nearest target vertex of each point, and whether the pair is usable (normals within
    about 70 degrees, gap under three times the median)."""
    gap, nearest = tree.query(points, workers=-1)
    agree = np.einsum("ij,ij->i", normals, target_normals[nearest]) > 0.3
    usable = agree & (gap <= 3.0 * np.median(gap[agree]) + 1e-12) if agree.any() else agree
    return gap, nearest, usable


def rigid_icp(source, source_normals, target, target_normals, *, iterations: int = 10) -> np.ndarray:
    """``source [N, 3]`` moved rigidly onto the target's vertices ``[M, 3]`` (step 1 of the
    module docstring, :func:`fourd.geometry.icp.rigid_icp`); returns the moved points
    ``[N, 3]``. ICP runs twice, from where the source is and with its centroid moved onto the
    target's, and the fit with the smaller median gap wins (a part that moves alone, an arm
    bending, drags the centroid away)."""
    tree = cKDTree(target)
    best, best_gap = source, np.inf
    for start in (source, source - source.mean(axis=0) + target.mean(axis=0)):
        fit = point_to_plane_icp(start, target, target_normals, source_normals=source_normals,
                                 iterations=iterations)
        moved = start @ fit.rotation.T + fit.translation
        gap, _, usable = _pairs(moved, source_normals @ fit.rotation.T, tree, target_normals)
        median = float(np.median(gap[usable])) if usable.any() else np.inf
        if median < best_gap:
            best, best_gap = moved, median
    return best


def geometric_anchors(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    *,
    spacing: float = 2.0,
    gap: float = 1.0,
    tolerance: float = 1.5,
    rigid_iterations: int = 10,
    iterations: int = 3,
    registration_iterations: int = 4,
    seed: int = 0,
) -> Alignment:
    """Anchors from the source to the target by a coarse non-rigid alignment (module docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    target_vertices : array [M, 3]
    target_faces : int array [G, 3]
        Both meshes oriented the same way.
    spacing : float
        Anchors about this far apart on the source (source edges; 2: about 9% of the vertices,
        which the patch map needs to reach most vertices without flow anchors, see
        ``benchmarks/METHODS.md``).
    gap : float
        Largest distance from an aligned source vertex to the target for it to become an
        anchor (source edges).
    tolerance : float
        Forward-backward tolerance (source edges).
    rigid_iterations, iterations : int
        Rigid and non-rigid ICP steps.
    registration_iterations : int
        Rotation fits of each non-rigid step.
    seed : int
        Seed of the anchors' spreading.

    Returns
    -------
    Alignment
    """
    source, sfaces = mesh_arrays(source_vertices, source_faces)
    target, tfaces = mesh_arrays(target_vertices, target_faces)
    edge = median_edge_length(source, sfaces)
    target_normals = vertex_normals(target, tfaces)
    source_normals = vertex_normals(source, sfaces)
    aligned = rigid_icp(source, source_normals, target, target_normals, iterations=rigid_iterations)
    tree = cKDTree(target)
    ids = np.arange(len(source))
    controls = ids[spread_anchors(Anchors(ids, ids, np.zeros((len(ids), 3))), source, 2.0 * edge, seed=seed)]
    for _ in range(iterations):
        normals = vertex_normals(aligned, sfaces)
        _, nearest, usable = _pairs(aligned[controls], normals[controls], tree, target_normals)
        if usable.sum() < 3:
            break
        known = np.zeros(len(source), dtype=bool)
        known[controls[usable]] = True
        points = np.zeros_like(source)
        points[controls[usable]] = target[nearest[usable]]
        placed = register_by_laplacian(source, sfaces, known, points, iterations=registration_iterations)
        aligned = np.where(np.isnan(placed), aligned, placed)

    # anchors: near candidates, oversampled, checked, then spread to the final density
    normals = vertex_normals(aligned, sfaces)
    distance, nearest, usable = _pairs(aligned, normals, tree, target_normals)
    candidates = np.flatnonzero(usable & (distance <= gap * edge + edge))
    empty = Anchors(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)))
    if len(candidates) < 3:
        return Alignment(empty, aligned, edge)
    dense = Anchors(candidates, candidates, np.zeros((len(candidates), 3)))
    candidates = candidates[spread_anchors(dense, source, 0.5 * spacing * edge, priority=-distance[candidates],
                                           seed=seed)]
    mesh = trimesh.Trimesh(target, tfaces, process=False)
    closest, exact, triangle = trimesh.proximity.closest_point(mesh, aligned[candidates])
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[triangle], closest)
    bary = np.clip(bary, 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    anchors = Anchors(candidates, triangle.astype(np.int64), bary)
    near = exact <= gap * edge
    _, back = cKDTree(aligned).query(target, workers=-1)
    ok = near & consistent_anchors(anchors, source, returned_points(anchors, tfaces, source[back]), tolerance * edge)
    anchors = anchors.subset(ok)
    kept = spread_anchors(anchors, source, spacing * edge, priority=-exact[ok], seed=seed)
    return Alignment(anchors.subset(kept), aligned, edge)
