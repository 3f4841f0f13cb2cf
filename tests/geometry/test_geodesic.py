from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.sparse.csgraph import dijkstra

from fourd.geometry.geodesic import edge_length_graph, geodesic_distances


def test_distances_are_scipys_dijkstra_from_the_nearest_seed_within_the_limit():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    vertices = sphere.vertices * (1.0 + 0.1 * np.random.default_rng(0).random((len(sphere.vertices), 1)))
    graph = edge_length_graph(vertices, sphere.faces)
    seeds, offsets = np.array([3, 700, 1500]), np.array([0.02, 0.0, 0.05])
    for limit in (0.3, 1.0, np.inf):
        rows = dijkstra(graph, indices=seeds, limit=limit)
        expected = np.min(rows + offsets[:, None], axis=0)
        got = geodesic_distances(graph, seeds, offsets, limit)
        assert np.array_equal(np.isfinite(got), np.isfinite(expected))
        assert np.allclose(got[np.isfinite(got)], expected[np.isfinite(expected)], rtol=0, atol=1e-12)
    assert 0 < np.isfinite(geodesic_distances(graph, seeds, offsets, 0.3)).mean() < 0.5


def test_the_edge_graph_has_every_edge_once_each_way_and_bad_seeds_are_refused():
    box = trimesh.creation.box()
    graph = edge_length_graph(box.vertices, box.faces)
    assert graph.nnz == 2 * 18 and (graph != graph.T).nnz == 0
    assert np.allclose(sorted(set(np.round(graph.data, 6))), [1.0, np.sqrt(2.0)])
    with pytest.raises(ValueError, match="out of range"):
        geodesic_distances(graph, [8])
    with pytest.raises(ValueError, match="one offset per seed"):
        geodesic_distances(graph, [0, 1], [0.0])
