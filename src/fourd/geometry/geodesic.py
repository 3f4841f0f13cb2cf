"""Geodesic distances on a mesh along its edges (Dijkstra), searched no farther than a limit,
so the cost is that of the ball reached, not of the mesh.

    >>> import numpy as np
    >>> vertices = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    >>> graph = edge_length_graph(vertices, np.array([[0, 1, 2], [0, 2, 3]]))
    >>> geodesic_distances(graph, [0]).round(3).tolist()
    [0.0, 1.0, 1.414, 1.0]
    >>> geodesic_distances(graph, [1, 3], [0.5, 0.0], limit=1.2).round(3).tolist()
    [1.0, 0.5, 1.0, 0.0]
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp

from fourd.geometry.heap import heap_pop, sift_up


def edge_length_graph(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    """Symmetric ``[N, N]`` graph of the mesh's edge lengths (an edge of two faces counted
    once; canonical CSR: sorted, no duplicates)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    i, j = faces.ravel(), np.roll(faces, -1, axis=1).ravel()
    a, b = np.minimum(i, j), np.maximum(i, j)
    _, first = np.unique(a * np.int64(len(vertices)) + b, return_index=True)
    a, b = a[first], b[first]
    length = np.linalg.norm(vertices[a] - vertices[b], axis=1)
    count = len(vertices)
    graph = sp.csr_matrix((np.r_[length, length], (np.r_[a, b], np.r_[b, a])), shape=(count, count))
    graph.sum_duplicates()
    return graph


class GeodesicBall(NamedTuple):
    """What one search reached: ``distances [N]`` (inf where no seed reached) and the
    ``vertices [K]`` with a finite distance, in the order first reached."""

    distances: np.ndarray
    vertices: np.ndarray


class GeodesicScratch(NamedTuple):
    """Working arrays of the searches on one graph of ``N`` vertices (:func:`geodesic_scratch`),
    reused from search to search so that a small ball costs what it reaches, not ``N``. Each
    search leaves them as it found them; one search at a time per scratch."""

    keys: np.ndarray  # [N] inf
    where: np.ndarray  # [N] -1
    heap: np.ndarray  # [N]
    reached: np.ndarray  # [N]


def geodesic_scratch(count: int) -> GeodesicScratch:
    """Fresh :class:`GeodesicScratch` for a graph of ``count`` vertices."""
    return GeodesicScratch(np.full(count, np.inf), np.full(count, -1, dtype=np.int64),
                           np.empty(count, dtype=np.int64), np.empty(count, dtype=np.int64))


def geodesic_distances(graph: sp.csr_matrix, seeds, offsets=None, limit: float = np.inf) -> np.ndarray:
    """Distance ``[N]`` of every vertex from the nearest seed, along ``graph``'s edges, plus
    that seed's offset: ``min over s of offsets[s] + d(seeds[s], v)``, a seed counting only
    where its own distance ``d`` is within ``limit`` (inf where none does).

    Parameters
    ----------
    graph : sparse [N, N]
        Edge lengths, each edge stored both ways (:func:`edge_length_graph`).
    seeds : int array [S]
    offsets : array [S], optional
        Added to each seed's distances (zero by default): the distance from a point inside a
        triangle to its corners, for instance.
    limit : float
        No vertex farther than this from a seed is reached from it.
    """
    return geodesic_ball(graph, seeds, offsets, limit).distances


def geodesic_ball(graph: sp.csr_matrix, seeds, offsets=None, limit: float = np.inf,
                  scratch: GeodesicScratch | None = None) -> GeodesicBall:
    """:func:`geodesic_distances` with the vertices it reached, searched with ``scratch``
    (:func:`geodesic_scratch` of the graph's size) when given: then the search touches only the
    vertices it reaches, apart from the ``[N]`` distances it returns."""
    if not (sp.issparse(graph) and graph.format == "csr"):
        graph = sp.csr_matrix(graph)
    seeds = np.atleast_1d(np.asarray(seeds, dtype=np.int64))
    offsets = np.zeros(len(seeds)) if offsets is None else np.atleast_1d(np.asarray(offsets, dtype=np.float64))
    if len(offsets) != len(seeds):
        raise ValueError(f"one offset per seed: {len(seeds)} seeds, {len(offsets)} offsets")
    if len(seeds) and (seeds.min() < 0 or seeds.max() >= graph.shape[0]):
        raise ValueError(f"seeds out of range for a graph of {graph.shape[0]} vertices")
    scratch = geodesic_scratch(graph.shape[0]) if scratch is None else scratch
    if len(scratch.keys) != graph.shape[0]:
        raise ValueError(f"scratch for {len(scratch.keys)} vertices, the graph has {graph.shape[0]}")
    weights = graph.data if graph.data.dtype == np.float64 else graph.data.astype(np.float64)
    distances, vertices = _nearest_seed_distances(graph.indptr, graph.indices, weights, seeds, offsets,
                                                  float(limit), *scratch)
    return GeodesicBall(distances, vertices)


@numba.njit(cache=True, nogil=True)
def _nearest_seed_distances(indptr, indices, weights, seeds, offsets, limit, keys, where, heap, reached):
    """Dijkstra from each seed in turn, within ``limit``; the minimum of distance plus offset,
    and the vertices reached. Only the vertices a search reaches are reset after it (``keys``
    inf and ``where`` -1 on entry and on return)."""
    count = len(indptr) - 1
    result = np.full(count, np.inf)
    found = np.empty(count, dtype=np.int64)
    total = 0
    for s in range(len(seeds)):
        seed = seeds[s]
        keys[seed] = 0.0
        heap[0] = seed
        where[seed] = 0
        size = 1
        touched = 1
        reached[0] = seed
        while size > 0:
            node, size = heap_pop(keys, heap, where, size)
            here = keys[node]
            if here + offsets[s] < result[node]:
                if result[node] == np.inf:
                    found[total] = node
                    total += 1
                result[node] = here + offsets[s]
            for e in range(indptr[node], indptr[node + 1]):
                other = indices[e]
                length = here + weights[e]
                if length > limit or length >= keys[other]:
                    continue
                if keys[other] == np.inf:
                    reached[touched] = other
                    touched += 1
                keys[other] = length
                if where[other] < 0:
                    heap[size] = other
                    where[other] = size
                    size += 1
                    sift_up(keys, heap, where, size - 1)
                else:
                    sift_up(keys, heap, where, where[other])
        for r in range(touched):
            keys[reached[r]] = np.inf
    return result, found[:total].copy()
