"""Nearest neighbours and the point spacing every default scale is derived from."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def knn(points: np.ndarray, k: int, *, tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest neighbours of every point, itself excluded.

    Parameters
    ----------
    points : ndarray [P, D]
    k : int

    Returns
    -------
    distances : ndarray float64 [P, k]
    indices : ndarray int64 [P, k]
    """
    k = int(min(k, len(points) - 1))
    if k < 1:
        raise ValueError("need at least two points for neighbours")
    tree = cKDTree(points) if tree is None else tree
    distances, indices = tree.query(points, k=k + 1, workers=-1)
    return distances[:, 1:], indices[:, 1:].astype(np.int64)


def neighbours_among(points: np.ndarray, indices: np.ndarray, keep: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` nearest neighbours of the kept points among the kept points, from the
    neighbour lists of all points.

    Parameters
    ----------
    points : ndarray [P, D]
    indices : ndarray int [P, K]
        Neighbour lists of every point (self excluded, nearest first, as :func:`knn` gives).
    keep : ndarray bool [P]
    k : int
        ``K`` should exceed it by a margin: rows with fewer than ``k`` kept neighbours among
        their ``K`` are queried again.

    Returns
    -------
    ndarray int64 [P', k]
        Indices into ``points[keep]`` (P' kept points), nearest first.
    """
    keep = np.asarray(keep, dtype=bool)
    kept_points = np.asarray(points)[keep]
    k = int(min(k, len(kept_points) - 1))
    if k < 1:
        raise ValueError("need at least two kept points for neighbours")
    renumber = np.cumsum(keep) - 1
    rows = np.asarray(indices)[keep]
    kept = keep[rows]
    # the kept neighbours first, each group in its distance order
    order = np.argsort(~kept, axis=1, kind="stable")[:, :k]
    out = renumber[np.take_along_axis(rows, order, axis=1)]
    short = np.flatnonzero(kept.sum(axis=1) < k)
    if len(short):
        _, again = cKDTree(kept_points).query(kept_points[short], k=k + 1, workers=-1)
        out[short] = again[:, 1:]
    return out.astype(np.int64)


def point_spacing(points: np.ndarray, *, sample: int = 20000, seed: int = 0) -> float:
    """Median distance from a point to its nearest neighbour (input units).

    At most ``sample`` points (chosen with ``seed``) are queried, against all points.
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 2:
        raise ValueError("need at least two points to measure spacing")
    tree = cKDTree(points)
    query = points
    if len(points) > sample:
        query = points[np.random.default_rng(seed).choice(len(points), sample, replace=False)]
    distances, _ = tree.query(query, k=2, workers=-1)
    spacing = float(np.median(distances[:, 1]))
    if spacing <= 0:
        positive = distances[:, 1][distances[:, 1] > 0]
        spacing = float(np.median(positive)) if len(positive) else 1.0
    return spacing
