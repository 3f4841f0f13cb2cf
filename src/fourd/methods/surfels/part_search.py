"""A rigid search per part before the non-rigid alignment (beyond the paper).

The alignment of sec. 3.2 is a non-rigid ICP: its correspondences are the data points nearest
each surfel, so a limb that moves several ``eps_sampl`` between two scans is beyond its reach
and stays behind (crane-50's fastest pairs: 60-80% of the fast part's motion left undone;
``experiments/surfels_alignment.py``). Here, after the whole-body rigid start, the surfels are
split into parts about ``size`` across (seeds ``size`` apart, each surfel to the seed nearest
along the graph ``T_S``), and each part is searched for on its own:

1. every translation on a grid of ``step`` up to ``reach`` away is scored by how many of the
   part's surfels it puts within ``step / 2`` of a data point whose normal agrees within 45
   degrees (ties: the shortest translation), among the data points that no surfel explains
   at the start (none within ``step``, normals agreeing): a part that moved left its data
   unexplained, and the data of the parts that did not move is theirs;
2. a point-to-plane rigid ICP refines the best one (:func:`fourd.geometry.icp.rigid_icp`);
3. the part moves only when that puts more of its surfels within ``step`` of such a data point
   than were near the data at its start, by at least ``gain`` of its surfels (so a part with
   more than ``1 - gain`` of its surfels near the data at the start is not searched at all).

The non-rigid alignment then starts from the parts' motions and its rigidity prior (eq. 9)
joins the seams. The search is a correspondence that does not come from proximity alone, and
it reaches only motions the grid covers (``reach``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from fourd.geometry.icp import rigid_icp
from fourd.geometry.neighbors import bucket_grid, nearest_within
from fourd.methods.surfels.topology import Topology, sample_surfels

#: Normals of a surfel and its data point agree within this many degrees.
MAX_ANGLE = 45.0
#: Queries per batch of :func:`part_offsets`' translations (memory: 40 bytes each).
OFFSET_QUERIES = 1_000_000
#: Parts with fewer surfels are not searched (a rigid fit needs a few).
MIN_PART = 6


class PartSearch(NamedTuple):
    """What :func:`part_search` runs with (input units).

    size : float
        The parts' size (the seeds' cube side).
    step : float
        The translation grid's step, and twice the distance at which a surfel counts as near
        a data point.
    reach : float
        The longest translation searched.
    gain : float
        Fraction of a part's surfels that must newly lie near data for the part to move.
    """

    size: float
    step: float
    reach: float
    gain: float


class PartStart(NamedTuple):
    """The surfels after :func:`part_search`.

    positions, normals : float64 [S, 3]
    rotations : float64 [S, 3, 3]
        Each surfel's part's rotation (the identity where the part did not move).
    moved, parts : int
        How many parts moved, of how many.
    """

    positions: np.ndarray
    normals: np.ndarray
    rotations: np.ndarray
    moved: int
    parts: int


def surfel_parts(positions: np.ndarray, topology: Topology, size: float) -> np.ndarray:
    """Part label [S] of each surfel of ``positions`` [S, 3]: the nearest, along the edges of
    ``topology``, of seeds at least ``size`` apart (:func:`spread_seeds`); a surfel no seed
    reaches (a piece of the graph without one) takes the nearest seed in space."""
    count = len(positions)
    seeds = spread_seeds(positions, size)
    i, j = topology.edges.T
    length = np.linalg.norm(positions[i] - positions[j], axis=1) + 1e-12 * size
    graph = coo_matrix((length, (i, j)), shape=(count, count)).tocsr()
    distance, _, source = dijkstra(
        graph, directed=False, indices=seeds, min_only=True, return_predecessors=True
    )
    seed_label = np.full(count, -1)
    seed_label[seeds] = np.arange(len(seeds))
    label = np.empty(count, dtype=np.int64)
    reached = np.isfinite(distance)
    label[reached] = seed_label[source[reached]]
    if not reached.all():
        label[~reached] = cKDTree(positions[seeds]).query(positions[~reached])[1]
    return label


def spread_seeds(positions: np.ndarray, size: float) -> np.ndarray:
    """Indices of surfels at least ``size`` apart covering ``positions`` [S, 3] to within
    ``size``: of the surfels kept one per cube of side ``size / 2``, greedily each one not
    within ``size`` of one kept before (one per cube of side ``size`` alone puts seeds
    side by side across the cubes' faces, and a small limb falls into several parts)."""
    candidates = sample_surfels(positions, 0.5 * size)
    tree = cKDTree(positions[candidates])
    blocked = np.zeros(len(candidates), dtype=bool)
    kept = []
    for k, near in enumerate(tree.query_ball_point(positions[candidates], size)):
        if not blocked[k]:
            kept.append(k)
            blocked[near] = True
    return candidates[np.asarray(kept, dtype=np.int64)]


def _near_data(positions, normals, tree, data_normals, within):
    """Bool [S]: a data point lies within ``within`` of each surfel, its normal agreeing."""
    distance, nearest = tree.query(positions, distance_upper_bound=within)
    near = np.isfinite(distance)
    near[near] = _agree(normals[near], data_normals[nearest[near]])
    return near


def _agree(normals: np.ndarray, data_normals: np.ndarray) -> np.ndarray:
    """Bool [N]: each of ``normals`` [N, 3] within :data:`MAX_ANGLE` of its ``data_normals``
    [N, 3] (unit)."""
    return np.einsum("ij,ij->i", normals, data_normals) >= np.cos(np.radians(MAX_ANGLE))


def part_offsets(
    positions: np.ndarray,
    normals: np.ndarray,
    label: np.ndarray,
    tree: cKDTree,
    data_normals: np.ndarray,
    step: float,
    reach: float,
) -> np.ndarray:
    """The best translation [K, 3] of each of the ``K`` parts on the grid of ``step`` within
    ``reach``: the one putting most of its surfels within ``step / 2`` of a data point of
    agreeing normal (ties: the shortest)."""
    steps = int(np.floor(reach / step))
    axis = np.arange(-steps, steps + 1) * step
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    length = np.linalg.norm(grid, axis=1)
    order = np.argsort(length, kind="stable")
    grid = grid[order[length[order] <= reach + 1e-9 * step]]
    parts = int(label.max()) + 1
    # every offset's surfels at once on a grid of the points (a k-d tree query per offset
    # took 4.4 of crane's 130 s): the nearest point within step / 2, its normal agreeing
    buckets, origin, side = bucket_grid(tree.data, 0.5 * step)
    score = np.zeros((len(grid), parts))
    chunk = max(1, OFFSET_QUERIES // max(1, len(positions)))
    for first in range(0, len(grid), chunk):
        shifts = grid[first : first + chunk]
        queries = (positions[None, :, :] + shifts[:, None, :]).reshape(-1, 3)
        bounds = np.full(len(queries), 0.5 * step)
        nearest, unsearched = nearest_within(buckets, origin, side, queries, bounds)
        if unsearched.any():
            distance, found = tree.query(queries[unsearched], distance_upper_bound=0.5 * step)
            nearest[unsearched] = np.where(np.isfinite(distance), found, -1)
        hit = np.flatnonzero(nearest >= 0)
        surfel = hit % len(positions)
        near = np.zeros(len(queries))
        near[hit] = _agree(normals[surfel], data_normals[nearest[hit]])
        which = np.repeat(np.arange(len(shifts)), len(positions)) * parts + np.tile(
            label, len(shifts)
        )
        score[first : first + len(shifts)] = np.bincount(
            which, weights=near, minlength=len(shifts) * parts
        ).reshape(len(shifts), parts)
    # the first offset of the best score, the grid being by increasing length
    return grid[np.argmax(score, axis=0)]


def part_search(
    positions: np.ndarray,
    normals: np.ndarray,
    topology: Topology,
    points: np.ndarray,
    point_normals: np.ndarray,
    search: PartSearch,
) -> PartStart:
    """Each part of the surfels ``positions``, ``normals`` [S, 3] (graph ``topology``)
    searched for among the data ``points`` [P, 3] with unit ``point_normals``, and moved
    where found (module docstring)."""
    count = len(positions)
    rotations = np.broadcast_to(np.eye(3), (count, 3, 3)).copy()
    moved_positions, moved_normals = positions.copy(), normals.copy()
    if count < MIN_PART or len(points) < MIN_PART:
        return PartStart(moved_positions, moved_normals, rotations, 0, 0)
    tree = cKDTree(points)
    label = surfel_parts(positions, topology, search.size)
    near = _near_data(positions, normals, tree, point_normals, search.step)
    size = np.bincount(label)
    # a part already near the data in more than 1 - gain of its surfels cannot gain enough
    searched = np.flatnonzero(
        (size >= MIN_PART) & (np.bincount(label, weights=near) < (1.0 - search.gain) * size)
    )
    # the parts are searched for among the data no surfel explains at the start: the data a
    # moved part left behind is explained by no one, the other parts' is theirs (two bodies
    # that touch do not take each other's surface)
    explained = _near_data(points, point_normals, cKDTree(positions), normals, search.step)
    if not len(searched) or (~explained).sum() < MIN_PART:
        return PartStart(moved_positions, moved_normals, rotations, 0, len(size))
    points, point_normals = points[~explained], point_normals[~explained]
    tree = cKDTree(points)
    local = np.full(len(size), -1)
    local[searched] = np.arange(len(searched))
    inside = np.flatnonzero(local[label] >= 0)
    offsets = part_offsets(
        positions[inside],
        normals[inside],
        local[label[inside]],
        tree,
        point_normals,
        search.step,
        search.reach,
    )
    moved = 0
    for part, offset in zip(searched, offsets, strict=True):
        index = np.flatnonzero(label == part)
        shifted = positions[index] + offset
        fit = rigid_icp(
            shifted,
            points,
            point_normals,
            source_normals=normals[index],
            max_turn=MAX_ANGLE,
            tree=tree,
        )
        p = shifted @ fit.rotation.T + fit.translation
        n = normals[index] @ fit.rotation.T
        found = _near_data(p, n, tree, point_normals, search.step).sum()
        if found > near[index].sum() + search.gain * len(index):
            moved_positions[index], moved_normals[index], rotations[index] = p, n, fit.rotation
            moved += 1
    return PartStart(moved_positions, moved_normals, rotations, moved, len(size))
