import numpy as np
import pytest

from fourd.geometry.outliers import (
    distance_ratio_inliers,
    remove_outliers,
    small_clusters,
    statistical_outliers,
)


def _fibonacci_sphere(count, radius=1.0):
    index = np.arange(count) + 0.5
    phi = np.arccos(1 - 2 * index / count)
    theta = np.pi * (1 + 5**0.5) * index
    return radius * np.stack(
        [np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1
    )


def _scan(seed=0, count=4000, noise=0.005, fraction=0.02):
    rng = np.random.default_rng(seed)
    surface = _fibonacci_sphere(count)
    surface += rng.normal(scale=noise, size=surface.shape)
    outliers = rng.uniform(-1.0, 1.0, size=(int(fraction * count), 3))
    return surface, outliers


def test_uniform_outliers_removed_surface_kept():
    surface, outliers = _scan()
    points = np.concatenate([surface, outliers])
    result = remove_outliers(points)
    kept_surface = result.inliers[: len(surface)].mean()
    # Outliers within a couple of spacings of the surface are indistinguishable from it;
    # judge recall on those clearly off the surface.
    spacing = 0.056
    off = np.abs(np.linalg.norm(outliers, axis=1) - 1.0) > 3 * spacing
    removed_far = (~result.inliers[len(surface) :])[off].mean()
    assert kept_surface > 0.98
    assert removed_far > 0.95
    assert result.inliers.dtype == bool and result.inliers.shape == (len(points),)
    assert not np.any(result.sparse & result.isolated)
    assert np.array_equal(result.inliers, ~(result.sparse | result.isolated))


def test_small_dense_cluster_removed():
    rng = np.random.default_rng(1)
    surface, _ = _scan(count=3000, fraction=0.0)
    # A tight structured cluster away from the surface: dense, so the statistical test keeps it.
    cluster = rng.normal(scale=0.01, size=(25, 3)) + [0.0, 0.0, 1.6]
    points = np.concatenate([surface, cluster])
    result = remove_outliers(points)
    assert not result.inliers[len(surface) :].any()
    assert result.isolated[len(surface) :].all()
    assert result.inliers[: len(surface)].mean() > 0.99
    assert result.clusters >= 2


def test_statistical_threshold_ignores_far_outliers():
    surface, outliers = _scan(count=3000)
    flagged_clean, limit_clean = statistical_outliers(surface, k=16, z=3.0)
    flagged, limit = statistical_outliers(np.concatenate([surface, outliers]), k=16, z=3.0)
    # The limit is set by the surface, not inflated by the outliers.
    assert limit < 1.5 * limit_clean
    assert flagged_clean.mean() < 0.02


def test_small_clusters_sizes():
    rng = np.random.default_rng(2)
    big = rng.uniform(0, 1, size=(500, 3)) * [1, 1, 0]
    small = rng.uniform(0, 0.05, size=(10, 3)) + [5, 5, 5]
    outliers, parts = small_clusters(np.concatenate([big, small]), radius=0.2, min_fraction=0.05)
    assert parts == 2
    assert outliers[500:].all() and not outliers[:500].any()


def test_tiny_input_keeps_everything():
    points = np.random.default_rng(3).normal(size=(8, 3))
    result = remove_outliers(points, k=16)
    assert result.inliers.all()


def test_scale_invariance():
    surface, outliers = _scan(seed=4)
    points = np.concatenate([surface, outliers])
    a = remove_outliers(points)
    b = remove_outliers(points * 10.0)
    assert np.array_equal(a.inliers, b.inliers)
    assert b.threshold == pytest.approx(10.0 * a.threshold)


def test_distance_ratio_inliers_drops_sparse_points_with_either_statistic():
    rng = np.random.default_rng(2)
    sphere = rng.normal(size=(4000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    points = np.concatenate([sphere, rng.uniform(-2, 2, size=(80, 3))])
    for statistic in ("kth", "mean"):
        keep = distance_ratio_inliers(points, k=8, factor=3.0, statistic=statistic)
        assert keep[:4000].mean() > 0.99 and keep[4000:].mean() < 0.2
    assert distance_ratio_inliers(points, factor=0.0).all()
    assert distance_ratio_inliers(points[:9], k=8).all()
    with pytest.raises(ValueError):
        distance_ratio_inliers(points, statistic="max")


def test_one_neighbour_query_serves_the_outlier_test_and_the_kept_points_neighbours():
    from fourd.geometry.neighbors import knn, neighbours_among

    rng = np.random.default_rng(3)
    sphere = rng.normal(size=(3000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    points = np.concatenate([sphere, rng.uniform(-2, 2, size=(150, 3))])
    distances, indices = knn(points, 12)
    keep = distance_ratio_inliers(points, k=8, statistic="mean", distances=distances)
    assert np.array_equal(keep, distance_ratio_inliers(points, k=8, statistic="mean"))
    # a few kept points lose many of their 12 neighbours: those rows are queried again
    keep[indices[0, :7]] = False
    got = neighbours_among(points, indices, keep, 6)
    _, expect = knn(points[keep], 6)
    assert np.array_equal(got, expect)
    with pytest.raises(ValueError, match="distances"):
        distance_ratio_inliers(points, k=8, distances=distances[:, :5])
