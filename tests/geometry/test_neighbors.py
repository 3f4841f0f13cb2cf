"""The grid search of knn gives exactly the k-d tree's neighbours."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from fourd.geometry.neighbors import GRID_MIN_POINTS, bucket_points, knn, nearest_within


def _surface_with_outliers(rng, count=6000, outliers=120):
    u, v = rng.uniform(0, 2 * np.pi, (2, count))
    # a torus scaled unevenly, so the density varies, plus uniform outliers in its box
    points = np.stack(
        [(2 + np.cos(v)) * np.cos(u), 0.4 * (2 + np.cos(v)) * np.sin(u), 3 * np.sin(v)], axis=1
    )
    lo, hi = points.min(axis=0), points.max(axis=0)
    return np.concatenate([points, rng.uniform(lo - 1, hi + 1, (outliers, 3))])


@pytest.mark.parametrize("k", [1, 8, 20])
def test_grid_knn_matches_the_kd_tree(k):
    points = _surface_with_outliers(np.random.default_rng(k))
    assert len(points) >= GRID_MIN_POINTS
    distances, indices = knn(points, k)
    expected_d, expected_i = cKDTree(points).query(points, k=k + 1)
    assert indices.shape == (len(points), k)
    np.testing.assert_array_equal(indices, expected_i[:, 1:])
    np.testing.assert_allclose(distances, expected_d[:, 1:], rtol=1e-12, atol=0)


def test_grid_knn_on_flat_and_duplicated_points():
    rng = np.random.default_rng(3)
    flat = np.c_[rng.uniform(0, 1, (3000, 2)), np.zeros(3000)]
    points = np.concatenate([flat, flat[:50]])  # 50 exact duplicates
    distances, indices = knn(points, 6)
    # a point is never its own neighbour; its duplicate is its nearest, at distance 0
    assert not np.any(indices == np.arange(len(points))[:, None])
    assert np.all(distances[:50, 0] == 0) and np.all(indices[:50, 0] == np.arange(3000, 3050))
    tree_d, _ = cKDTree(points).query(points, k=7)
    np.testing.assert_allclose(distances, tree_d[:, 1:], rtol=1e-12, atol=0)


def test_nearest_within_matches_the_kd_tree_within_each_bound():
    rng = np.random.default_rng(5)
    points = _surface_with_outliers(rng, count=3000, outliers=60)
    queries = _surface_with_outliers(rng, count=500, outliers=40) * 1.05
    cell = 0.3
    origin = points.min(axis=0)
    grid = bucket_points(points, origin, cell)
    bounds = rng.uniform(0.0, 0.6, len(queries))
    bounds[:20] = -1.0  # skipped
    indices, unsearched = nearest_within(grid, origin, cell, queries, bounds, max_cells=64)
    distances, expected = cKDTree(points).query(queries, k=1)
    within = distances <= bounds
    searched = ~unsearched & (bounds >= 0)
    assert searched.sum() > 250 and unsearched.sum() > 10 and np.sum(searched & within) > 100
    np.testing.assert_array_equal(indices[searched & within], expected[searched & within])
    assert np.all(indices[~(searched & within)] == -1)
    # a query is unsearched only when its bound's block spans more than max_cells cells
    assert np.all(bounds[unsearched] > cell * (64 ** (1 / 3) - 1) / 2)
