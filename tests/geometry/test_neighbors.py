"""The grid search of knn gives exactly the k-d tree's neighbours."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from fourd.geometry.neighbors import GRID_MIN_POINTS, knn


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
