"""Combinatorial topology and enclosed volume of triangle meshes: what the metrics report per frame.

Examples
--------
>>> import trimesh
>>> sphere = trimesh.creation.icosphere(1)
>>> topology(sphere.faces).closed_manifold
True
>>> round(enclosed_volume(sphere.vertices, sphere.faces), 2)
3.66
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fourd.geometry.fans import pinched_vertices
from fourd.geometry.meshes import enclosed_volume

__all__ = ["Topology", "enclosed_volume", "topology"]


class Topology(NamedTuple):
    """Combinatorial topology of one triangle mesh (only vertices used by faces count).
    ``closed_manifold``: no boundary side, no side of more than two faces and no pinched vertex
    (two or more fans of faces meeting at it, :mod:`fourd.geometry.fans`)."""

    components: int
    boundary_loops: int
    euler: int
    nonmanifold_edges: int
    boundary_edges: int
    oriented: bool
    closed_manifold: bool
    pinched_vertices: int = 0


def topology(faces: np.ndarray, vertex_count: int | None = None) -> Topology:
    """Components, boundary loops, Euler characteristic and manifoldness of ``faces [F, 3]``.

    Faces with a repeated corner are ignored. Components are connected through shared vertices;
    boundary loops are the connected pieces of the edges used by one face only; a pinched vertex
    is one where separate fans of faces meet.
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    if len(faces) == 0:
        return Topology(0, 0, 0, 0, 0, True, False)
    n = int(faces.max()) + 1 if vertex_count is None else int(vertex_count)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    undirected = np.sort(directed, axis=1)
    keys = undirected[:, 0] * n + undirected[:, 1]
    unique_keys, counts = np.unique(keys, return_counts=True)
    boundary = unique_keys[counts == 1]
    nonmanifold = int(np.count_nonzero(counts > 2))
    oriented = len(np.unique(directed[:, 0] * n + directed[:, 1])) == len(directed)
    used = np.unique(faces)
    euler = len(used) - len(unique_keys) + len(faces)

    def pieces(a: np.ndarray, b: np.ndarray, nodes: np.ndarray) -> int:
        graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)).tocsr()
        _, labels = connected_components(graph, directed=False)
        return len(np.unique(labels[nodes]))

    components = pieces(undirected[:, 0], undirected[:, 1], used)
    if len(boundary):
        ba, bb = boundary // n, boundary % n
        loops = pieces(ba, bb, np.unique(np.concatenate([ba, bb])))
    else:
        loops = 0
    pinched = len(pinched_vertices(faces))
    closed = len(boundary) == 0 and nonmanifold == 0 and pinched == 0
    return Topology(components, loops, int(euler), nonmanifold, int(len(boundary)), bool(oriented), closed, pinched)
