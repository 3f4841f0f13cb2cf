from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.sparse.csgraph import dijkstra

from fourd.geometry.geodesic import (
    edge_length_graph,
    geodesic_ball,
    geodesic_distances,
    geodesic_scratch,
)


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


def test_a_ball_searched_with_scratch_is_the_same_search_and_leaves_the_scratch_as_found():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    graph = edge_length_graph(sphere.vertices, sphere.faces)
    scratch = geodesic_scratch(len(sphere.vertices))
    rng = np.random.default_rng(1)
    for _ in range(20):
        seeds = rng.choice(len(sphere.vertices), size=rng.integers(1, 4), replace=False)
        offsets, limit = 0.05 * rng.random(len(seeds)), float(rng.uniform(0.1, 0.6))
        ball = geodesic_ball(graph, seeds, offsets, limit, scratch)
        assert np.array_equal(ball.distances, geodesic_distances(graph, seeds, offsets, limit))
        assert sorted(ball.vertices.tolist()) == np.flatnonzero(np.isfinite(ball.distances)).tolist()
        assert np.all(np.isinf(scratch.keys)) and np.all(scratch.where == -1)
    with pytest.raises(ValueError, match="scratch for"):
        geodesic_ball(graph, [0], limit=0.1, scratch=geodesic_scratch(5))


def test_the_edge_graph_has_every_edge_once_each_way_and_bad_seeds_are_refused():
    box = trimesh.creation.box()
    graph = edge_length_graph(box.vertices, box.faces)
    assert graph.nnz == 2 * 18 and (graph != graph.T).nnz == 0
    assert np.allclose(sorted(set(np.round(graph.data, 6))), [1.0, np.sqrt(2.0)])
    with pytest.raises(ValueError, match="out of range"):
        geodesic_distances(graph, [8])
    with pytest.raises(ValueError, match="one offset per seed"):
        geodesic_distances(graph, [0, 1], [0.0])
