"""The fans of faces around each vertex, and pinched vertices split apart.

The faces around a vertex of a manifold mesh form one fan: each is joined to the next by a side
through the vertex. Where two cones of faces touch only at their tips (two pieces of a surface
meeting at a vertex, a hole's rim crossing itself), the vertex has two fans: a *pinch*, which
tools such as Blender's "select non-manifold" report, and which breaks what needs a disk around
every vertex (a UV unwrap, a subdivision, a half-edge structure). Giving each extra fan its own
copy of the vertex, at the same place, makes the surface a manifold without moving anything.

Examples
--------
>>> import numpy as np
>>> bow_tie = np.array([[0, 1, 2], [0, 3, 4]])  # two triangles touching at vertex 0
>>> pinched_vertices(bow_tie).tolist()
[0]
>>> faces, source = split_pinches(bow_tie, 5)
>>> faces.tolist(), source.tolist()
([[0, 1, 2], [5, 3, 4]], [0, 1, 2, 3, 4, 0])
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from fourd.geometry.meshes import face_adjacency, face_pieces

__all__ = ["corner_fans", "fan_count", "fragments", "pinched_vertices", "split_pinches"]


def corner_fans(faces: np.ndarray) -> np.ndarray:
    """int64 ``[F, 3]``: a label per corner of ``faces [F, 3]``, the same for two corners of a
    vertex exactly when their faces are joined around it by sides through it (one fan)."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    pairs, sides = face_adjacency(faces)
    links = []
    for end in (0, 1):
        vertex = sides[:, end]
        corner = [3 * pairs[:, k] + np.argmax(faces[pairs[:, k]] == vertex[:, None], axis=1) for k in (0, 1)]
        links.append(np.stack(corner, axis=1))
    links = np.concatenate(links) if links else np.zeros((0, 2), dtype=np.int64)
    graph = sp.coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(3 * len(faces),) * 2)
    _, label = connected_components(graph, directed=False)
    return label.reshape(-1, 3).astype(np.int64)


def _fans(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(fan_vertex [K], corner_fan [3F])``: the vertex of each fan (sorted by vertex) and the
    fan of each corner."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    span = np.int64(max(3 * len(faces), 1))
    keys, corner_fan = np.unique(faces.ravel() * span + corner_fans(faces).ravel(), return_inverse=True)
    return keys // span, corner_fan.ravel()


def fan_count(faces: np.ndarray) -> int:
    """The vertices of ``faces [F, 3]`` counted once per fan: a manifold vertex once, a pinch
    once per cone of faces touching there."""
    return len(_fans(faces)[0])


def pinched_vertices(faces: np.ndarray) -> np.ndarray:
    """int64 ``[P]``: the vertices of ``faces [F, 3]`` with more than one fan, sorted."""
    fan_vertex, _ = _fans(faces)
    return np.unique(fan_vertex[1:][fan_vertex[1:] == fan_vertex[:-1]])


def split_pinches(faces: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(faces [F, 3], source [count + P'])``: ``faces`` with every fan but the first of a
    pinched vertex given a new vertex ``count, count + 1, ...``, and the vertex each vertex is a
    copy of (``source[:count]`` is ``arange(count)``), so ``vertices[source]`` places the copies
    where their vertex is, in any frame."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    fan_vertex, corner_fan = _fans(faces)
    first = np.ones(len(fan_vertex), dtype=bool)
    first[1:] = fan_vertex[1:] != fan_vertex[:-1]
    number = np.where(first, fan_vertex, int(count) + np.cumsum(~first) - 1)
    source = np.concatenate([np.arange(int(count), dtype=np.int64), fan_vertex[~first]])
    return number[corner_fan].reshape(-1, 3), source


def fragments(faces: np.ndarray, count: int, *, hanging: float = 100.0, loose: float = 1000.0) -> np.ndarray:
    """bool ``[F]``: the faces of ``faces [F, 3]`` (``count`` vertices) in a fragment: a piece
    (faces joined by sides) that touches a piece at least ``hanging`` times its face count at a
    vertex (a flap hanging by a pinch, where a scan's surface frays), or that has at most
    ``1 / loose`` of the largest piece's faces (a crumb a few point spacings across, below what
    the sampling resolves). Pieces of like size touching at a point (two bodies in contact) and
    a small object of its own are kept."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    pieces, piece = face_pieces(faces)
    size = np.bincount(piece, minlength=pieces)
    corner_piece, vertex = np.repeat(piece, 3), faces.ravel()
    largest = np.zeros(int(count), dtype=np.int64)
    np.maximum.at(largest, vertex, size[corner_piece])
    dropped = loose * size <= size.max()
    np.logical_or.at(dropped, corner_piece, largest[vertex] >= hanging * size[corner_piece])
    return dropped[piece]
