"""Anchor set refinement (thesis section 5.4.4): more anchors where the surfaces touch.

Where anchors are sparse, patches grow large and align badly. The thesis first maps with
small patches, which leaves vertices unmapped where anchors are sparse; the source is then
registered in the target's frame by its Laplacian coordinates with the mapped vertices held
(:mod:`~fourd.methods.assembly.registration`), and every unmapped vertex that lands within a
"nearly zero" distance of the target becomes an anchor at its closest target point. Roughly
registered in the target's pose, a closest point is a reliable match, which it is not
between two poses. An unmapped vertex that lands away from the target (a hole there, or
geometry the target does not share) gets none. The anchors added are spread
(:func:`~fourd.methods.assembly.anchors.spread_anchors`): none nearer than the spacing to an
anchor there was or to another added one, the closest to the target first.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.meshes import median_edge_length, mesh_arrays
from fourd.methods.assembly.anchors import Anchors, spread_anchors
from fourd.methods.assembly.options import RefineOptions
from fourd.methods.assembly.registration import register_by_laplacian
from fourd.methods.assembly.relax import mapped_points

log = logging.getLogger("fourd.methods.assembly.refine")


class Refinement(NamedTuple):
    """What :func:`refine_anchors` found.

    anchors : Anchors
        The anchors given, then the ones added.
    added : int64 [K]
        Source vertices of the anchors added.
    registered : float64 [N, 3]
        The source registered in the target's frame (NaN where it could not be placed).
    distance : float64 [N]
        Distance of each unmapped, registered vertex from the target (input units; NaN for
        the others).
    """

    anchors: Anchors
    added: np.ndarray
    registered: np.ndarray
    distance: np.ndarray


def refine_anchors(
    source_vertices: np.ndarray,
    source_faces: np.ndarray,
    target_vertices: np.ndarray,
    target_faces: np.ndarray,
    anchors: Anchors,
    faces: np.ndarray,
    barycentric: np.ndarray,
    options: RefineOptions | None = None,
) -> Refinement:
    """Add anchors at the unmapped source vertices that the Laplacian registration lays on the
    target (module docstring).

    Parameters
    ----------
    source_vertices : array [N, 3]
    source_faces : int array [F, 3]
    target_vertices : array [M, 3]
    target_faces : int array [G, 3]
    anchors : Anchors
        The anchors there are.
    faces : int array [N]
        The map (e.g. a cross-parameterisation with small patches): target triangle of each
        source vertex, -1 where unmapped.
    barycentric : array [N, 3]
    options : RefineOptions, optional

    Returns
    -------
    Refinement
    """
    options = RefineOptions() if options is None else options
    source_vertices, source_faces = mesh_arrays(source_vertices, source_faces)
    target_vertices, target_faces = mesh_arrays(target_vertices, target_faces)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1)
    known = faces >= 0
    points = np.nan_to_num(mapped_points(target_vertices, target_faces, faces, barycentric))
    registered = register_by_laplacian(source_vertices, source_faces, known, points,
                                       laplacian=options.laplacian, iterations=options.iterations)
    edge = median_edge_length(source_vertices, source_faces)
    candidates = np.flatnonzero(~known & np.isfinite(registered).all(axis=1))
    distance = np.full(len(source_vertices), np.nan)
    if len(candidates) == 0:
        return Refinement(anchors, np.zeros(0, dtype=np.int64), registered, distance)
    triangle, bary, _, gap = closest_points_on_mesh(target_vertices, target_faces, registered[candidates])
    distance[candidates] = gap
    touching = gap <= options.touch * edge
    new = Anchors(candidates[touching], triangle[touching], bary[touching])
    every = Anchors.join(anchors, new)
    old = np.arange(len(every.source)) < len(anchors.source)
    priority = np.r_[np.full(len(anchors.source), np.inf), -gap[touching]]
    kept = spread_anchors(every, source_vertices, options.spacing * edge, priority=priority, keep=old)
    added = every.subset(kept & ~old)
    log.debug("anchor refinement: %d unmapped, %d touching, %d added", len(candidates),
              int(touching.sum()), len(added.source))
    return Refinement(Anchors.join(anchors, added), added.source, registered, distance)
