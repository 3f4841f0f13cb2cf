"""Doubled layers: small pieces of a mesh that lie along a larger surface of it.

A surface meshed from samples with a border clipping (``surfels``' sec. 3.3) can cut a sliver
off where the samples thin out, mesh a second layer of a surface the scan saw twice a cell or
two beside it, or leave a bubble of a few faces around one grid point beside the surface. The
body around it is then closed (the hole a sliver left gets a membrane), and the small piece
stays: an open one keeps the whole mesh from being watertight, and neither adds anything the
body lacks, since it lies within the meshing's resolution of the body's surface. A small piece
whose surface mostly lies farther out (a limb's end cut off, a ball held against the body) is
kept: it is surface nothing else covers.

Examples
--------
>>> import numpy as np, trimesh
>>> ball = trimesh.creation.icosphere(3)  # 1,280 faces, edges about 0.15
>>> sliver = [[0.0, 0, 1.02], [0.05, 0, 1.02], [0, 0.05, 1.02]]  # a triangle just outside it
>>> far = [[0.0, 0, 1.5], [0.05, 0, 1.5], [0, 0.05, 1.5]]
>>> vertices = np.concatenate([ball.vertices, sliver, far])
>>> faces = np.concatenate([ball.faces, [[642, 643, 644], [645, 646, 647]]])
>>> np.flatnonzero(doubled_layers(vertices, faces)).tolist()
[1280]
"""

from __future__ import annotations

import numpy as np

from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.meshes import face_pieces, median_edge_length

__all__ = ["DOUBLED_REACH", "DOUBLED_SMALL", "doubled_layers"]

#: Median distance, in median edge lengths, within which a small piece lies along another
#: surface to count as a doubled layer. The marching cubes resolve two layers a cell apart at
#: best; crane's and crane-90's slivers lie 0.7 edges from the body (median; at most 1.8-2.6), and
#: crane-90's bubble of 8 faces 0.8.
DOUBLED_REACH = 2.0

#: A piece is small when the largest piece has at least this many times its faces.
DOUBLED_SMALL = 100.0


def doubled_layers(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    reach: float = DOUBLED_REACH,
    small: float = DOUBLED_SMALL,
) -> np.ndarray:
    """bool ``[F]``: the faces of ``faces [F, 3]`` (over ``vertices [N, 3]``) in a doubled
    layer: a piece (faces joined by sides) with at most ``1 / small`` of the largest piece's
    faces whose vertices lie at a median distance of at most ``reach`` median edge lengths
    from the surface of the pieces that are not small."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    none = np.zeros(len(faces), dtype=bool)
    if len(faces) == 0:
        return none
    pieces, piece = face_pieces(faces)
    if pieces < 2:
        return none
    size = np.bincount(piece, minlength=pieces)
    candidate = small * size <= size.max()
    if not candidate.any():
        return none
    vertex_piece = np.full(len(vertices), -1, dtype=np.int64)
    vertex_piece[faces.ravel()] = np.repeat(piece, 3)
    near = np.flatnonzero(candidate[np.maximum(vertex_piece, 0)] & (vertex_piece >= 0))
    distance = closest_points_on_mesh(vertices, faces[~candidate[piece]], vertices[near]).distances
    # each candidate piece's median distance, all pieces at once (a noisy mesh has thousands)
    label = vertex_piece[near]
    order = np.lexsort((distance, label))
    label, distance = label[order], distance[order]
    starts = np.flatnonzero(np.r_[True, label[1:] != label[:-1]])
    counts = np.diff(np.r_[starts, len(label)])
    median = 0.5 * (distance[starts + (counts - 1) // 2] + distance[starts + counts // 2])
    is_doubled = np.zeros(pieces, dtype=bool)
    is_doubled[label[starts]] = median <= reach * median_edge_length(vertices, faces)
    return is_doubled[piece]
