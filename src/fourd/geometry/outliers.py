"""Outlier removal for scanned point sets: statistical (sparse neighbourhoods) and small
isolated clusters (connected components of the neighbour graph).

References
----------
Rusu, Marton, Blodow, Dolha, Beetz: Towards 3D point cloud based object maps for household
environments, Robotics and Autonomous Systems 56(11), 2008 (statistical outlier removal,
section 4.1).
Rusu: Semantic 3D object maps for everyday manipulation in human living environments, PhD
thesis, TU München 2009 (Euclidean cluster extraction, section 6.2).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fourd.geometry.neighbors import knn, point_spacing

log = logging.getLogger("fourd.geometry.outliers")


class Outliers(NamedTuple):
    """The outcome of :func:`remove_outliers`.

    inliers : bool [P]
        Points kept.
    sparse : bool [P]
        Points flagged by the statistical test (mean neighbour distance too large).
    isolated : bool [P]
        Points (not already sparse) in clusters too small to be part of the surface.
    threshold : float
        Mean-neighbour-distance limit the statistical test used (input units).
    cluster_radius : float
        Linking distance used for the clusters (input units).
    clusters : int
        Number of clusters among the non-sparse points (before removing the small ones).
    """

    inliers: np.ndarray
    sparse: np.ndarray
    isolated: np.ndarray
    threshold: float
    cluster_radius: float
    clusters: int


def statistical_outliers(
    points: np.ndarray,
    *,
    k: int = 16,
    z: float = 5.0,
    distances: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Flag points whose mean distance to their ``k`` nearest neighbours exceeds
    ``mean + z * std`` of that quantity over all points.

    The mean and standard deviation are taken over the points below the median plus ten
    median absolute deviations, so that a few per cent of far outliers do not inflate the
    limit (the plain statistic of Rusu et al. would let outliers near the surface through).

    Parameters
    ----------
    points : ndarray [P, 3]
    k : int
    z : float
    distances : ndarray [P, >=k], optional
        Precomputed sorted neighbour distances (self excluded).

    Returns
    -------
    outliers : ndarray bool [P]
    threshold : float
    """
    points = np.asarray(points, dtype=np.float64)
    if z <= 0:
        raise ValueError(f"z must be positive, got {z}")
    if distances is None:
        distances, _ = knn(points, k)
    mean = distances[:, :k].mean(axis=1)
    median = np.median(mean)
    mad = np.median(np.abs(mean - median))
    core = mean[mean <= median + 10.0 * max(mad, 1e-12 * max(median, 1e-300))]
    threshold = float(core.mean() + z * core.std())
    return mean > threshold, threshold


def small_clusters(
    points: np.ndarray,
    *,
    radius: float,
    min_fraction: float = 0.01,
    min_points: int = 0,
    k: int = 16,
    indices: np.ndarray | None = None,
    distances: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Flag points in clusters smaller than ``max(min_points, min_fraction * largest)``.

    Clusters are the connected components of the graph linking each point to those of its
    ``k`` nearest neighbours closer than ``radius``.

    Returns
    -------
    outliers : ndarray bool [P]
    clusters : int
        Number of components found.
    """
    points = np.asarray(points, dtype=np.float64)
    count = len(points)
    if count < 2:
        return np.zeros(count, dtype=bool), count
    if indices is None or distances is None:
        distances, indices = knn(points, k)
    linked = distances <= radius
    rows = np.repeat(np.arange(count), indices.shape[1])[linked.ravel()]
    cols = indices[linked]
    graph = sp.csr_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(count, count))
    parts, labels = connected_components(graph, directed=False)
    sizes = np.bincount(labels, minlength=parts)
    limit = max(float(min_points), float(min_fraction) * sizes.max())
    return sizes[labels] < limit, int(parts)


def distance_ratio_inliers(
    points: np.ndarray,
    *,
    k: int = 8,
    factor: float = 3.0,
    statistic: str = "kth",
    distances: np.ndarray | None = None,
) -> np.ndarray:
    """Boolean mask [P] of the points kept by a neighbour-distance ratio test: a point is
    dropped when its neighbour distance (``statistic`` "kth": to its ``k``-th neighbour;
    "mean": mean over its ``k`` nearest) exceeds ``factor`` times the median of that distance.
    ``factor`` 0 keeps every point; so do sets of at most ``k + 1`` points. ``distances``
    [P, >= k] (optional): the neighbour distances already at hand (self excluded, nearest
    first, as :func:`~fourd.geometry.neighbors.knn` gives)."""
    if statistic not in ("kth", "mean"):
        raise ValueError(f"statistic must be kth or mean, got {statistic!r}")
    points = np.asarray(points, dtype=np.float64)
    if factor <= 0 or len(points) <= k + 1:
        return np.ones(len(points), dtype=bool)
    if distances is None:
        distances, _ = knn(points, k)
    elif distances.shape[0] != len(points) or distances.shape[1] < k:
        raise ValueError(f"distances must be [{len(points)}, >= {k}], got {list(distances.shape)}")
    distances = distances[:, :k]
    distance = distances[:, -1] if statistic == "kth" else distances.mean(axis=1)
    return distance <= factor * max(float(np.median(distance)), 1e-12)


def remove_outliers(
    points: np.ndarray,
    *,
    k: int = 16,
    z: float = 5.0,
    cluster_radius: float | None = None,
    min_cluster_fraction: float = 0.01,
    min_cluster_points: int | None = None,
    spacing: float | None = None,
) -> Outliers:
    """Statistical outlier removal followed by removal of small isolated clusters.

    Parameters
    ----------
    points : ndarray [P, 3]
    k : int
        Neighbours for both tests.
    z : float
        Standard deviations above the mean neighbour distance beyond which a point is sparse.
    cluster_radius : float, optional
        Linking distance for the clusters; default 3 point spacings.
    min_cluster_fraction : float
        Clusters smaller than this fraction of the largest one are removed.
    min_cluster_points : int, optional
        Clusters smaller than this are removed whatever their fraction; default ``k``.
    spacing : float, optional
        The point spacing if already known (:func:`fourd.geometry.neighbors.point_spacing`).

    Returns
    -------
    Outliers

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> sphere = rng.normal(size=(3000, 3)); sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    >>> noisy = np.concatenate([sphere, rng.uniform(-1, 1, size=(60, 3))])
    >>> result = remove_outliers(noisy)
    >>> bool(result.inliers[:3000].mean() > 0.97 and result.inliers[3000:].mean() < 0.5)
    True
    """
    points = np.asarray(points, dtype=np.float64)
    count = len(points)
    if count <= k + 1:
        log.debug("outlier removal skipped: %d points", count)
        empty = np.zeros(count, dtype=bool)
        return Outliers(np.ones(count, dtype=bool), empty, empty.copy(), np.inf, np.inf, 1)
    tree = cKDTree(points)
    distances, indices = knn(points, k, tree=tree)
    sparse, threshold = statistical_outliers(points, k=k, z=z, distances=distances)
    if spacing is None:
        spacing = point_spacing(points)
    radius = 3.0 * spacing if cluster_radius is None else float(cluster_radius)
    keep = np.flatnonzero(~sparse)
    isolated = np.zeros(count, dtype=bool)
    clusters = 0
    if len(keep) > 1:
        # Neighbour lists restricted to surviving points: reuse the full lists, drop links to
        # sparse points (their ranks beyond k are not needed for linking within ``radius``).
        remap = np.full(count, -1, dtype=np.int64)
        remap[keep] = np.arange(len(keep))
        sub_indices = remap[indices[keep]]
        sub_distances = np.where(sub_indices >= 0, distances[keep], np.inf)
        sub_indices = np.where(sub_indices >= 0, sub_indices, 0)
        minimum = k if min_cluster_points is None else int(min_cluster_points)
        small, clusters = small_clusters(
            points[keep],
            radius=radius,
            min_fraction=min_cluster_fraction,
            min_points=minimum,
            indices=sub_indices,
            distances=sub_distances,
        )
        isolated[keep[small]] = True
    inliers = ~(sparse | isolated)
    log.debug(
        "outliers: %d sparse (limit %.3g), %d in small clusters of %d, %d of %d kept",
        int(sparse.sum()),
        threshold,
        int(isolated.sum()),
        clusters,
        int(inliers.sum()),
        count,
    )
    return Outliers(inliers, sparse, isolated, threshold, radius, clusters)
