"""Nearest neighbours and the point spacing every default scale is derived from."""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

#: Below this many 3D points :func:`knn` queries a k-d tree instead of a grid.
GRID_MIN_POINTS = 2000
#: Grid cell side in typical k-th neighbour distances (measured fastest on the scans).
GRID_CELL = 1.2
#: Largest number of grid cells (coarser cells beyond).
GRID_MAX_CELLS = 8_000_000
#: Points per task of the parallel grid search.
CHUNK = 256


def knn(points: np.ndarray, k: int, *, tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest neighbours of every point, itself excluded.

    Sets of at least :data:`GRID_MIN_POINTS` 3D points (and no ``tree`` given) are searched
    on a uniform grid (:func:`_grid_neighbours`; 1.3-1.4 times as fast as ``cKDTree`` on the
    scans, 2 threads), others with a k-d tree: the same neighbours in the same order (the
    grid puts equal distances in index order, and a point's duplicates after itself).

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
    points = np.asarray(points)
    if tree is None and points.ndim == 2 and points.shape[1] == 3 and len(points) >= GRID_MIN_POINTS:
        return _grid_neighbours(np.ascontiguousarray(points, dtype=np.float64), k)
    tree = cKDTree(points) if tree is None else tree
    distances, indices = tree.query(points, k=k + 1, workers=-1)
    return distances[:, 1:], indices[:, 1:].astype(np.int64)


def _grid_neighbours(points: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`knn` on a uniform grid of cells :data:`GRID_CELL` times the median ``k``-th
    neighbour distance wide, keyed z-fastest so that a row of cells is one run of points.

    That distance is measured on a first grid (cells sized as if the points covered the box's
    largest face) at 256 of the points. A point whose ``k``-th neighbour lies farther than
    its block of 27 cells reaches (sparse parts, outliers) searches blocks twice as wide
    until it does, so the result is exact whatever the cell size.
    """
    count = len(points)
    origin = points.min(axis=0)
    extent = np.maximum(np.ptp(points, axis=0), 1e-12)
    faces = np.sort(extent)[1:]
    cell = _coarse_enough(extent, float(np.sqrt(faces[0] * faces[1] * (k + 1) / count)) * GRID_CELL)
    squared = np.empty((count, k + 1))
    indices = np.empty((count, k + 1), dtype=np.int64)
    grid = bucket_points(points, origin, cell)
    probe = np.linspace(0, count - 1, min(count, 256)).astype(np.int64)
    _grid_knn(*grid, origin, cell, probe, squared, indices)
    measured = _coarse_enough(extent, GRID_CELL * float(np.sqrt(np.median(squared[grid[1][probe], k]))))
    if abs(measured - cell) > 0.1 * cell:
        cell = measured
        grid = bucket_points(points, origin, cell)
    _grid_knn(*grid, origin, cell, np.arange(count), squared, indices)
    return np.sqrt(squared[:, 1:]), indices[:, 1:]


def _coarse_enough(extent, cell):
    """``cell``, enlarged until a grid over ``extent`` [3] has at most :data:`GRID_MAX_CELLS`
    cells (also for flat or linear point sets)."""
    cell = max(cell, float(extent.max()) * 1e-9)
    while np.prod(np.floor(extent / cell) + 1) > GRID_MAX_CELLS:
        cell *= 1.25
    return cell


def bucket_points(points: np.ndarray, origin: np.ndarray, cell: float):
    """Points [P, 3] sorted into the cells of a uniform grid (corner ``origin`` [3], side
    ``cell``, over the points' extent), keyed z-fastest so that a row of cells along z holds
    one contiguous run of points.

    Returns ``(sorted points [P, 3], order [P]`` (the original index of each sorted point),
    ``starts [cells + 1]`` (where each cell's run starts), ``dims [3])``.
    """
    if len(points) == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(2, np.int64), np.ones(3, np.int64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    index = np.floor((points - origin) / cell).astype(np.int64)
    dims = index.max(axis=0) + 1
    key = (index[:, 0] * dims[1] + index[:, 1]) * dims[2] + index[:, 2]
    starts = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=len(starts) - 1), out=starts[1:])
    order = np.empty(len(points), dtype=np.int64)
    ordered = np.empty_like(points)
    _scatter_by_key(key, points, starts[:-1].copy(), order, ordered)
    return ordered, order, starts, dims


@numba.njit(cache=True)
def _scatter_by_key(key, points, fill, order, ordered):
    """Stable counting sort of ``points`` [P, 3] by cell ``key`` [P] given each cell's run
    start ``fill`` [cells] (advanced as the cell fills): the sorted indices into ``order``
    [P] and the sorted points into ``ordered`` [P, 3] (half the cost of a stable argsort of
    the keys, which the registration pays every iteration)."""
    for i in range(len(key)):
        at = fill[key[i]]
        fill[key[i]] = at + 1
        order[at] = i
        ordered[at, 0] = points[i, 0]
        ordered[at, 1] = points[i, 1]
        ordered[at, 2] = points[i, 2]


@numba.njit(cache=True, inline="always")
def cell_of(x0, x1, x2, origin, cell):
    """The (unclamped) cell indices of the point ``(x0, x1, x2)`` in a grid of
    :func:`bucket_points` (corner ``origin`` [3], side ``cell``), for compiled kernels."""
    return (
        np.int64(np.floor((x0 - origin[0]) / cell)),
        np.int64(np.floor((x1 - origin[1]) / cell)),
        np.int64(np.floor((x2 - origin[2]) / cell)),
    )


@numba.njit(cache=True, parallel=True, nogil=True)
def _grid_knn(sorted_points, ids, starts, dims, origin, cell, rows, out_d2, out_idx):
    """For the sorted points at ``rows`` (``ids`` [P]: the sorted points' original indices)
    their ``k + 1`` nearest, themselves first: squared distances and original indices into
    ``out_d2`` / ``out_idx`` [P, k + 1] at their original rows."""
    kk = out_d2.shape[1]
    chunks = (len(rows) + CHUNK - 1) // CHUNK
    for chunk in numba.prange(chunks):
        best_d2 = np.empty(kk)
        best_id = np.empty(kk, np.int64)
        for r in range(chunk * CHUNK, min((chunk + 1) * CHUNK, len(rows))):
            q = rows[r]
            x0 = sorted_points[q, 0]
            x1 = sorted_points[q, 1]
            x2 = sorted_points[q, 2]
            c0, c1, c2 = cell_of(x0, x1, x2, origin, cell)
            reach = 1
            while True:
                for a in range(kk):
                    best_d2[a] = np.inf
                    best_id[a] = -1
                # the point itself first (also ahead of a duplicate of it)
                best_d2[0] = -1.0
                best_id[0] = ids[q]
                worst = np.inf
                z0 = max(c2 - reach, 0)
                z1 = min(c2 + reach, dims[2] - 1)
                for i in range(max(c0 - reach, 0), min(c0 + reach + 1, dims[0])):
                    for j in range(max(c1 - reach, 0), min(c1 + reach + 1, dims[1])):
                        row = (i * dims[1] + j) * dims[2]
                        for p in range(starts[row + z0], starts[row + z1 + 1]):
                            if p == q:
                                continue
                            d0 = x0 - sorted_points[p, 0]
                            d1 = x1 - sorted_points[p, 1]
                            d2_ = x2 - sorted_points[p, 2]
                            d2 = d0 * d0 + d1 * d1 + d2_ * d2_
                            if d2 > worst:
                                continue
                            other = ids[p]
                            if d2 == worst and other > best_id[kk - 1]:
                                continue
                            a = kk - 1
                            while a > 1 and (
                                best_d2[a - 1] > d2 or (best_d2[a - 1] == d2 and best_id[a - 1] > other)
                            ):
                                best_d2[a] = best_d2[a - 1]
                                best_id[a] = best_id[a - 1]
                                a -= 1
                            best_d2[a] = d2
                            best_id[a] = other
                            worst = best_d2[kk - 1]
                # every point within this distance lies in the block searched (the grid's
                # outside is empty)
                covered = np.inf
                if c0 - reach > 0:
                    covered = min(covered, x0 - (origin[0] + (c0 - reach) * cell))
                if c0 + reach + 1 < dims[0]:
                    covered = min(covered, origin[0] + (c0 + reach + 1) * cell - x0)
                if c1 - reach > 0:
                    covered = min(covered, x1 - (origin[1] + (c1 - reach) * cell))
                if c1 + reach + 1 < dims[1]:
                    covered = min(covered, origin[1] + (c1 + reach + 1) * cell - x1)
                if c2 - reach > 0:
                    covered = min(covered, x2 - (origin[2] + (c2 - reach) * cell))
                if c2 + reach + 1 < dims[2]:
                    covered = min(covered, origin[2] + (c2 + reach + 1) * cell - x2)
                if worst <= covered * covered:
                    break
                reach *= 2
            row = ids[q]
            out_d2[row, 0] = 0.0
            out_idx[row, 0] = row
            for a in range(1, kk):
                out_d2[row, a] = best_d2[a]
                out_idx[row, a] = best_id[a]


#: Most grid cells :func:`nearest_within` scans for one query; a query whose bound spans
#: more is left unsearched for the caller to answer another way (a k-d tree).
NEAREST_MAX_CELLS = 64


def bucket_grid(points: np.ndarray, cell: float):
    """``points`` [P >= 1, 3] in a grid of cells about ``cell`` wide (coarser where that would
    exceed :data:`GRID_MAX_CELLS`) over their box, for :func:`nearest_within`: ``(grid,
    origin, cell)`` with ``grid`` the :func:`bucket_points` output."""
    origin, far = _box(points)
    cell = _coarse_enough(far - origin, cell)
    return bucket_points(points, origin, cell), origin, cell


@numba.njit(cache=True)
def _box(points):
    """Smallest and largest coordinates [3] of ``points`` [P >= 1, 3] (a tenth of the cost of
    numpy's reductions along the short axis, which :func:`bucket_grid` pays every
    registration iteration)."""
    low = points[0].copy()
    high = points[0].copy()
    for i in range(1, len(points)):
        for a in range(3):
            low[a] = min(low[a], points[i, a])
            high[a] = max(high[a], points[i, a])
    return low, high


def nearest_within(
    grid, origin: np.ndarray, cell: float, queries: np.ndarray, bounds: np.ndarray,
    max_cells: int = NEAREST_MAX_CELLS,
) -> tuple[np.ndarray, np.ndarray]:
    """The nearest of the points bucketed in ``grid`` (:func:`bucket_points` with corner
    ``origin`` [3] and side ``cell``; :func:`bucket_grid` gives all three) within a bound of
    its own for each of ``queries``
    [Q, 3]: exact, and fast where the bounds are small (a warm start's distance to the
    previous nearest point).

    Parameters
    ----------
    bounds : ndarray [Q]
        Largest distance searched, inclusive; negative: the query is skipped (none).

    Returns
    -------
    indices : ndarray int64 [Q]
        Original index of the nearest point, -1 where none lies within the bound.
    unsearched : ndarray bool [Q]
        Queries whose bound spans more than ``max_cells`` cells: not searched (index -1).
    """
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    indices = np.full(len(queries), -1, dtype=np.int64)
    unsearched = np.zeros(len(queries), dtype=bool)
    if len(grid[0]):
        _nearest_within(
            *grid, np.asarray(origin, dtype=np.float64), float(cell), queries,
            np.ascontiguousarray(bounds, dtype=np.float64), int(max_cells), indices, unsearched,
        )
    return indices, unsearched


@numba.njit(cache=True, parallel=True, nogil=True)
def _nearest_within(
    sorted_points, ids, starts, dims, origin, cell, queries, bounds, max_cells, out_idx,
    out_unsearched,
):
    """:func:`nearest_within`'s search, into ``out_idx`` / ``out_unsearched`` [Q]."""
    for q in numba.prange(len(queries)):
        bound = bounds[q]
        if bound < 0:
            continue
        if not bound <= cell * max_cells:
            out_unsearched[q] = True
            continue
        x0 = queries[q, 0]
        x1 = queries[q, 1]
        x2 = queries[q, 2]
        lo0, lo1, lo2 = cell_of(x0 - bound, x1 - bound, x2 - bound, origin, cell)
        hi0, hi1, hi2 = cell_of(x0 + bound, x1 + bound, x2 + bound, origin, cell)
        lo0 = max(lo0, 0)
        lo1 = max(lo1, 0)
        lo2 = max(lo2, 0)
        hi0 = min(hi0, dims[0] - 1)
        hi1 = min(hi1, dims[1] - 1)
        hi2 = min(hi2, dims[2] - 1)
        if hi0 < lo0 or hi1 < lo1 or hi2 < lo2:
            continue
        if (hi0 - lo0 + 1) * (hi1 - lo1 + 1) * (hi2 - lo2 + 1) > max_cells:
            out_unsearched[q] = True
            continue
        best = bound * bound
        found = -1
        for i in range(lo0, hi0 + 1):
            for j in range(lo1, hi1 + 1):
                row = (i * dims[1] + j) * dims[2]
                for p in range(starts[row + lo2], starts[row + hi2 + 1]):
                    d0 = x0 - sorted_points[p, 0]
                    d1 = x1 - sorted_points[p, 1]
                    d2 = x2 - sorted_points[p, 2]
                    d = d0 * d0 + d1 * d1 + d2 * d2
                    if d < best or (d == best and found < 0):
                        best = d
                        found = p
        if found >= 0:
            out_idx[q] = ids[found]


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
