"""The fitted garment's correspondences taken from the base mesh instead of the fit (Popa's
thesis, 3.6.2 and 3.7).

The frame-to-frame fit (:mod:`.fit`) puts the template on every frame's surface, but without a
texture to follow it lets the cloth slide along that surface, and the sliding adds up over the
frames. The thesis ties its frames together differently: each frame is mapped onto one base
mesh, the tetrahedron of the openings' anchors (:mod:`.base_mesh`), on its own, and a vertex is
the point with the same base coordinates in every frame. Here the fitted surfaces are those
frames: complete, with the template's four clean openings (the surface completion of 3.7
already done), so the thesis' map applies to them as it does to clean meshes. The first
frame's vertices are carried into every other frame's fitted surface through the base, each
frame's paths between the anchors guided by the first frame's
(:func:`~fourd.methods.garment.base_mesh.base_charts`). Points stay on each frame's fitted
surface; only where on it each vertex lies changes.
"""

from __future__ import annotations

import logging

import numpy as np

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.rotations import procrustes
from fourd.methods.garment.base_mesh import (
    base_mesh,
    closed_surface,
    map_through_base,
    parameterize_onto_base,
    vertex_base_coordinates,
)
from fourd.progress import progress

log = logging.getLogger("fourd.methods.garment")

__all__ = ["GUIDE_REACH", "correspondence_through_base"]

#: A frame's paths between its anchors follow the first frame's (moved by the anchors'
#: similarity) within about this fraction of the anchors' median distance.
GUIDE_REACH = 0.3


def _reach(anchors: np.ndarray) -> float:
    distances = np.linalg.norm(anchors[:, None] - anchors[None], axis=2)[np.triu_indices(len(anchors), 1)]
    return GUIDE_REACH * float(np.median(distances))


def correspondence_through_base(vertices: np.ndarray, faces: np.ndarray, openings: list,
                                anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's vertices moved, on that frame's surface, to the points with the first
    frame's vertices' base coordinates (module docstring).

    Parameters
    ----------
    vertices : array [T, N, 3]
        The fitted template in every frame.
    faces : int array [F, 3]
        Its connectivity; its only boundary loops are the openings.
    openings : list of int arrays
        The openings' boundary loops, in the anchors' order (3 or 4 of them).
    anchors : array [T, K, 3]
        The openings' off-surface anchors in every frame.

    Returns
    -------
    vertices : float64 [T, N, 3]
    carried : bool [T]
        The frames whose vertices were carried through the base (the first frame always; a
        frame whose map onto the base folds keeps its fitted vertices).
    """
    vertices = np.array(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    anchors = np.asarray(anchors, dtype=np.float64)
    frames, count = vertices.shape[:2]
    carried = np.zeros(frames, dtype=bool)
    carried[0] = True
    base = base_mesh(anchors[0])
    closed, closed_faces, apex = closed_surface(vertices[0], faces, openings, anchors[0])
    first = parameterize_onto_base(closed, closed_faces, apex, base)
    facets, barycentric = vertex_base_coordinates(first, count)
    paths = [closed[path] for path in first.charts.paths]
    for t in progress(range(1, frames), desc="garment: correspondence through the base mesh", unit="frame"):
        move = procrustes(anchors[0], anchors[t], with_scale=True)
        guides = [move.scale * path @ move.rotation.T + move.translation for path in paths]
        try:
            frame, frame_faces, frame_apex = closed_surface(vertices[t], faces, openings, anchors[t])
            mapped = parameterize_onto_base(frame, frame_faces, frame_apex, base, guides=guides,
                                            reach=_reach(anchors[t]))
        except InputError as error:
            log.warning("garment: frame %d cannot be mapped onto the base mesh (%s); its fit is kept", t, error)
            continue
        if not np.isfinite(mapped.stretch):
            log.warning("garment: frame %d's map onto the base mesh folds (stretch %s); its fit is kept", t,
                        mapped.stretch)
            continue
        vertices[t], _, _ = map_through_base(facets, barycentric, frame, frame_faces, mapped)
        carried[t] = True
    return vertices, carried


def template_openings(faces: np.ndarray, count: int, members: list) -> list:
    """The template's boundary loops in the order of ``members`` (per opening, some of its
    boundary vertices): each opening's whole loop."""
    loops = boundary_loops(faces, count)
    ordered = []
    for vertices_on in members:
        holding = [loop for loop in loops if np.isin(vertices_on, loop).any()]
        if len(holding) != 1:
            raise InputError("the template's openings are not its boundary loops")
        ordered.append(holding[0])
    return ordered
