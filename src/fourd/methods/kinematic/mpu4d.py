"""Four-dimensional Multi-level Partition of Unity implicits over a hextree (16-ary tree).

The space-time points ``(x, y, z, w)`` with ``w = delta * t`` and normals ``(n, 0)`` are
approximated by local shape functions on the leaves of an adaptive 16-ary tree; the global
function is their partition-of-unity blend with quadratic B-spline weights:

    f(x) = sum_i b_i(x) Q_i(x) / sum_i b_i(x),   b_i(x) = B(3 |x - c_i| / (2 R_i))

Local shape functions (chosen per cell as in Ohtake et al. 2003, extended to 4D):

* a generic 4D quadric (15 coefficients) fitted with auxiliary points at the cell's centre and
  16 corners, when the local normals spread over more than a half sphere;
* a low-variate quadric ``h = q(u)`` over the 3D tangent space of the mean normal otherwise;
* at edges and corners (the low-variate quadric fails the error test and the normals spread),
  the normals are clustered on the normal sphere with the k-means / LBG loop of the paper
  (stop when the sum of cluster variances drops below ``epsilon_c = 0.1``), one low-variate
  quadric is fitted per cluster and they are combined by Boolean max (intersection, convex
  edge) or min (union, concave edge).

A cell is split into 16 children while the local error (max Taubin distance
``|Q(p)| / |grad Q(p)|`` over its points) is above the MPU error and it holds at least
``min_points`` points; cells with fewer points grow their support until they hold
``min_points`` and become leaves. Every local function is stored as a quadric in world
coordinates, so evaluation is one compiled kernel (tree traversal with support bounding boxes,
parallel over query points; many queries at one time read a grid of the leaves that meet that
time slice instead). Memory is linear in the number of points.

References
----------
Süßmuth, Winter, Greiner: Reconstructing animated meshes from time-varying point clouds,
SGP 2008 (000_00387fefe94cc850.txt), sections 2-3.
Ohtake, Belyaev, Alexa, Turk, Seidel: Multi-level partition of unity implicits, SIGGRAPH 2003.
Yau, Srihari: A hierarchical data structure for multidimensional digital images, CACM 1983.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import NamedTuple

import numba
import numpy as np
from scipy.spatial import cKDTree

from fourd.methods.kinematic.mpu_eval import _evaluate, _evaluate_slice, _slice_grid
from fourd.methods.kinematic.mpu_fit import (
    _CORNERS,
    KIND_FEATURE,
    KIND_GENERIC,
    KIND_LOWVARIATE,
    MAX_PIECES,
    _fit_cells,
)
from fourd.methods.kinematic.mpu_tree import _ball_csr, _child_counts, _child_fill, z_order

log = logging.getLogger("fourd.methods.kinematic.mpu4d")

#: Evaluations of at least this many points at one time use that time slice's leaf grid.
SLICE_MIN_QUERIES = 64
#: Time slices whose leaf grids are kept.
SLICE_CACHE = 4
#: Largest leaf grid of a time slice (cells).
SLICE_MAX_CELLS = 2_000_000


@dataclass(frozen=True)
class MPUOptions:
    """Parameters of the 4D MPU fit (lengths in 4D units, i.e. input units).

    Attributes
    ----------
    error : float
        The MPU error epsilon_0: a cell whose local function's max Taubin distance to its points
        exceeds it is split. Required (> 0); the method derives it from the point spacing.
    min_points : int
        N_min: cells with fewer points grow their support until they hold this many and stop
        splitting. Must be at least 15 (the coefficients of a 4D quadric).
    alpha : float
        Support radius ``R = alpha * cell diagonal`` (Ohtake et al.: 0.75; a 4D cell of side
        ``s`` has diagonal ``2 s``, so the support reaches past the cell's corners).
    max_depth : int
        Safety limit on the tree depth.
    cluster_epsilon : float
        epsilon_c of the LBG normal clustering's stopping rule (the paper: 0.1).
    feature_angle : float
        Normals must spread over at least this angle (radians) from their mean before the
        edge/corner fit is tried.
    max_fit_points : int
        Cells holding more points (the coarse levels, which are split anyway) fit a regular
        subsample of this many.
    error_quantile : float
        The local error is this quantile of the points' Taubin distances, and the normal
        spread test (generic quadric when normals point away from their mean) uses the
        complementary quantile of ``n . mean``: 1.0 is the maximum / minimum (Ohtake et al.,
        the paper); below 1 a few outliers or flipped normals no longer force generic fits and
        splitting down to ``min_points`` (beyond the paper, for scans with outliers).
    """

    error: float
    min_points: int = 40
    alpha: float = 0.75
    max_depth: int = 12
    cluster_epsilon: float = 0.1
    feature_angle: float = np.pi / 4
    max_fit_points: int = 400
    error_quantile: float = 1.0

    def __post_init__(self):
        if not (self.error > 0):
            raise ValueError(f"MPU error must be positive, got {self.error}")
        if self.min_points < 15:
            raise ValueError(f"min_points must be at least 15, got {self.min_points}")
        if not (0.5 <= self.alpha <= 3.0):
            raise ValueError(f"alpha must lie in [0.5, 3], got {self.alpha}")


class MPUStats(NamedTuple):
    """Diagnostics of a fit: counts of cells and leaves by kind, depth reached."""

    cells: int
    leaves: int
    lowvariate: int
    generic: int
    feature: int
    depth: int
    max_leaf_error: float



@dataclass(frozen=True, eq=False)
class MPU4D:
    """A fitted 4D MPU implicit ``f(x, y, z, w)`` (negative inside); see :func:`fit_mpu4d`.

    Flat arrays: hextree nodes (children contiguous, support bounding boxes for traversal),
    leaves (centre, support radius, pieces) and pieces (world quadrics
    ``(x-o)^T M (x-o) + g.(x-o) + c``).
    """

    child_start: np.ndarray
    child_count: np.ndarray
    node_lo: np.ndarray
    node_hi: np.ndarray
    node_leaf: np.ndarray
    leaf_centre: np.ndarray
    leaf_radius: np.ndarray
    leaf_start: np.ndarray
    leaf_count: np.ndarray
    leaf_op: np.ndarray
    leaf_kind: np.ndarray
    leaf_error: np.ndarray
    M: np.ndarray
    g: np.ndarray
    c: np.ndarray
    origins: np.ndarray
    outside: float
    stats: MPUStats
    _slices: OrderedDict = field(default_factory=OrderedDict, repr=False)

    def evaluate(
        self, points4: np.ndarray, *, gradient: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """``f`` [M] and, if asked, ``grad f`` [M, 4] at 4D points [M, 4].

        Where no leaf support covers a point, ``f`` is ``outside`` (positive) and the gradient 0.
        Many points at one time ``w`` (the sliding's queries) are evaluated from a grid of
        the leaves that meet that time slice (built once per slice, the last
        ``SLICE_CACHE`` kept), other points by descending the tree.
        """
        q = np.ascontiguousarray(points4, dtype=np.float64).reshape(-1, 4)
        values = np.empty(len(q))
        grads = np.empty((len(q) if gradient else 0, 4))
        # the leaves and their pieces, then the outputs: shared by both kernels
        leaves = (
            self.leaf_centre,
            self.leaf_radius,
            self.leaf_start,
            self.leaf_count,
            self.leaf_op,
            self.M,
            self.g,
            self.c,
            self.origins,
            float(self.outside),
            values,
            grads,
            max(1, min(len(q), 8 * numba.get_num_threads())),
        )
        if len(q) >= SLICE_MIN_QUERIES and np.all(q[:, 3] == q[0, 3]):
            _evaluate_slice(q, gradient, *self._slice(float(q[0, 3])), *leaves)
        elif len(q):
            tree = (self.child_start, self.child_count, self.node_lo, self.node_hi, self.node_leaf)
            _evaluate(q, gradient, *tree, *leaves)
        return values, (grads if gradient else None)

    def __call__(self, points4: np.ndarray) -> np.ndarray:
        return self.evaluate(points4, gradient=False)[0]

    def _slice(self, w: float):
        """Grids of the leaves whose support meets the time slice ``w`` (cached): one grid per
        size class (support radius in ``[s, 2 s)`` with ``s`` the smallest radius times a power
        of two, cells of size ``s``), so that every leaf is listed in at most 125 cells."""
        if w in self._slices:
            self._slices.move_to_end(w)
            return self._slices[w]
        dw = w - self.leaf_centre[:, 3]
        meets = self.leaf_radius**2 - dw * dw > 0
        ids = np.flatnonzero(meets)
        smallest = float(self.leaf_radius.min()) if len(self.leaf_radius) else 1.0
        size_class = np.floor(np.log2(self.leaf_radius[ids] / smallest)).astype(np.int64)
        los, cells, dims_all, offsets, starts, leaves = [], [], [], [], [], []
        cell_total, leaf_total = 0, 0
        for k in np.unique(size_class):
            members = ids[size_class == k]
            centres = self.leaf_centre[members, :3]
            radii = self.leaf_radius[members, None]
            lo = (centres - radii).min(axis=0)
            hi = (centres + radii).max(axis=0)
            cell = max(smallest * 2.0**k, float(np.prod(hi - lo) / SLICE_MAX_CELLS) ** (1 / 3))
            dims = np.maximum(np.ceil((hi - lo) / cell).astype(np.int64), 1)
            start, listed = _slice_grid(
                self.leaf_centre, self.leaf_radius, members, w, lo, cell, dims
            )
            los.append(lo)
            cells.append(cell)
            dims_all.append(dims)
            offsets.append(cell_total)
            starts.append(start[:-1] + leaf_total)
            leaves.append(listed)
            cell_total += len(start) - 1
            leaf_total += len(listed)
        grids = (
            np.array(los, dtype=np.float64).reshape(-1, 3),
            np.array(cells, dtype=np.float64),
            np.array(dims_all, dtype=np.int64).reshape(-1, 3),
            np.array(offsets, dtype=np.int64),
            np.concatenate(starts + [np.array([leaf_total], dtype=np.int64)]),
            np.concatenate(leaves) if leaves else np.zeros(0, np.int32),
        )
        self._slices[w] = grids
        while len(self._slices) > SLICE_CACHE:
            self._slices.popitem(last=False)
        return grids

    @property
    def nbytes(self) -> int:
        return sum(
            getattr(self, name).nbytes
            for name in self.__dataclass_fields__
            if isinstance(getattr(self, name), np.ndarray)
        )


def mpu_arrays(mpu: MPU4D) -> dict[str, np.ndarray]:
    """A fitted :class:`MPU4D` as plain arrays (a cache entry; :func:`mpu_from_arrays` reads
    it back exactly)."""
    arrays = {
        name: getattr(mpu, name)
        for name in mpu.__dataclass_fields__
        if isinstance(getattr(mpu, name), np.ndarray)
    }
    arrays["outside"] = np.array(mpu.outside)
    arrays["stats"] = np.array(mpu.stats, dtype=np.float64)
    return arrays


def mpu_from_arrays(arrays) -> MPU4D:
    """The :class:`MPU4D` whose :func:`mpu_arrays` are ``arrays``."""
    stats = [float(v) for v in arrays["stats"]]
    fields = {
        name: np.asarray(arrays[name])
        for name in MPU4D.__dataclass_fields__
        if name not in ("outside", "stats", "_slices")
    }
    return MPU4D(
        **fields,
        outside=float(arrays["outside"]),
        stats=MPUStats(*(int(v) for v in stats[:-1]), stats[-1]),
    )


def fit_mpu4d(points: np.ndarray, normals: np.ndarray, *, options: MPUOptions) -> MPU4D:
    """Fit a 4D MPU implicit to oriented 4D points.

    Parameters
    ----------
    points : ndarray float [P, 4]
        Space-time points ``(x, y, z, delta * t)``.
    normals : ndarray float [P, 4]
        Unit outward normals (the paper uses ``(n, 0)``).
    options : MPUOptions

    Returns
    -------
    MPU4D
        Negative inside, zero on the surface; roughly a signed distance near the data.

    References
    ----------
    000_00387fefe94cc850.txt section 3; Ohtake et al. 2003 sections 2-4.
    """
    X = np.ascontiguousarray(points, dtype=np.float64)
    N = np.ascontiguousarray(normals, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 4 or N.shape != X.shape:
        raise ValueError(f"points and normals must both be [P, 4], got {X.shape} and {N.shape}")
    if len(X) < options.min_points:
        raise ValueError(f"need at least {options.min_points} points, got {len(X)}")
    lengths = np.linalg.norm(N, axis=1)
    N = N / np.maximum(lengths, 1e-300)[:, None]
    # points in Z order: a cell's point list then lies in a few runs of memory (measured on
    # dfaust-hopping: the fit's list kernels about twice as fast)
    order = z_order(X)
    X, N = np.ascontiguousarray(X[order]), np.ascontiguousarray(N[order])
    tree = cKDTree(X)
    lo, hi = X.min(axis=0), X.max(axis=0)
    half0 = 0.5 * float(np.max(hi - lo)) * 1.01 + 1e-12
    cos_feature = float(np.cos(options.feature_angle))

    # per level: centres, half sizes; output accumulators
    level_centres = np.array([(lo + hi) / 2.0])
    level_parent = np.array([-1])
    nodes_centre, nodes_parent, nodes_leaf_local, nodes_level = [], [], [], []
    leaves = {
        k: []
        for k in ("centre", "radius", "M", "g", "c", "origins", "count", "op", "kind", "error")
    }
    node_offset = 0
    depth = 0
    total_cells = 0
    parent_global = level_parent
    # point lists of the cells' supports of the level radius R0 (CSR) and counts of points in
    # the cells' boxes; children's lists are filtered from their parent's list (a child's
    # support lies inside its parent's support since alpha >= 0.5) instead of tree queries
    base_ptr, base_idx = _ball_csr(tree, level_centres, np.array([4.0 * options.alpha * half0]))
    base_idx = np.sort(base_idx)
    base_inside = np.diff(base_ptr)
    while len(level_centres):
        half = half0 / 2.0**depth
        R0 = 4.0 * options.alpha * half
        counts = np.diff(base_ptr)
        sparse = counts < options.min_points
        if sparse.any() and depth > 0:
            # a sparse cell with no point in its own box only grazes the data with its support:
            # its neighbours cover that data, and a grown support would fit a poor function
            drop = np.flatnonzero(sparse & (base_inside == 0))
            if len(drop):
                keep = np.ones(len(level_centres), dtype=bool)
                keep[drop] = False
                base_idx = base_idx[np.repeat(keep, counts)]
                level_centres = level_centres[keep]
                parent_global = parent_global[keep]
                counts = counts[keep]
                sparse = sparse[keep]
                base_ptr = np.zeros(len(counts) + 1, dtype=np.int64)
                np.cumsum(counts, out=base_ptr[1:])
        cells = len(level_centres)
        radii = np.full(cells, R0)
        indptr, indices = base_ptr, base_idx
        if sparse.any():
            k = options.min_points
            dist, _ = tree.query(level_centres[sparse], k=k)
            radii[sparse] = np.maximum(dist[:, -1] * 1.0001, R0)
            sp_ptr, sp_idx = _ball_csr(tree, level_centres[sparse], radii[sparse])
            lengths = counts.copy()
            lengths[sparse] = np.diff(sp_ptr)
            starts = base_ptr[:-1].copy()
            starts[sparse] = len(base_idx) + sp_ptr[:-1]
            indptr = np.zeros(cells + 1, dtype=np.int64)
            np.cumsum(lengths, out=indptr[1:])
            gather = np.repeat(starts - indptr[:-1], lengths) + np.arange(int(indptr[-1]))
            indices = np.concatenate([base_idx, sp_idx])[gather]
        M = np.zeros((cells, MAX_PIECES, 4, 4))
        g = np.zeros((cells, MAX_PIECES, 4))
        c = np.zeros((cells, MAX_PIECES))
        origins = np.zeros((cells, MAX_PIECES, 4))
        count = np.zeros(cells, dtype=np.int64)
        op = np.zeros(cells, dtype=np.int64)
        kind = np.zeros(cells, dtype=np.int64)
        error = np.zeros(cells)
        _fit_cells(
            X,
            N,
            indptr,
            indices,
            level_centres,
            radii,
            np.full(cells, half),
            options.error,
            options.cluster_epsilon,
            cos_feature,
            _CORNERS,
            M,
            g,
            c,
            origins,
            count,
            op,
            kind,
            error,
            options.max_fit_points,
            6 * options.min_points,
            options.error_quantile,
        )
        split = (error > options.error) & ~sparse & (depth < options.max_depth)
        # children of split cells that have data in their support; a split cell none of whose
        # children holds data stays a leaf
        child_half = half / 2.0
        child_radius = 4.0 * options.alpha * child_half
        parents = np.flatnonzero(split)
        children = (level_centres[parents][:, None, :] + child_half * _CORNERS[None]).reshape(-1, 4)
        child_counts = np.zeros(len(children), dtype=np.int64)
        child_inside = np.zeros(len(children), dtype=np.int64)
        child_masks = np.zeros(len(indices), dtype=np.uint16)
        if len(children):
            _child_counts(
                X,
                indptr,
                indices,
                parents,
                level_centres,
                child_half,
                child_radius,
                child_counts,
                child_inside,
                child_masks,
            )
        has_data = child_counts > 0
        barren = ~has_data.reshape(-1, 16).any(axis=1)
        split[parents[barren]] = False
        keep_child = (has_data.reshape(-1, 16) & ~barren[:, None]).ravel()
        child_parent = np.repeat(parents + node_offset, 16)
        leaf_local = np.full(cells, -1, dtype=np.int64)
        is_leaf = ~split
        first_leaf = sum(len(x) for x in leaves["radius"])
        leaf_local[is_leaf] = first_leaf + np.arange(int(is_leaf.sum()))
        for key, value in (
            ("centre", level_centres),
            ("radius", radii),
            ("M", M),
            ("g", g),
            ("c", c),
            ("origins", origins),
            ("count", count),
            ("op", op),
            ("kind", kind),
            ("error", error),
        ):
            leaves[key].append(value[is_leaf])
        nodes_centre.append(level_centres)
        nodes_parent.append(parent_global)
        nodes_leaf_local.append(leaf_local)
        nodes_level.append(np.full(cells, depth))
        total_cells += cells
        if not keep_child.any():
            break
        node_offset += cells
        slot = np.full(len(children), -1, dtype=np.int64)
        slot[keep_child] = np.arange(int(keep_child.sum()))
        base_ptr = np.zeros(int(keep_child.sum()) + 1, dtype=np.int64)
        np.cumsum(child_counts[keep_child], out=base_ptr[1:])
        base_idx = np.empty(int(base_ptr[-1]), dtype=np.int64)
        _child_fill(indptr, indices, parents, child_masks, slot, base_ptr, base_idx)
        base_inside = child_inside[keep_child]
        level_centres = children[keep_child]
        parent_global = child_parent[keep_child]
        depth += 1

    centre_all = np.concatenate(nodes_centre)
    parent_all = np.concatenate(nodes_parent)
    leaf_of_node = np.concatenate(nodes_leaf_local)
    node_count = len(centre_all)
    # children are contiguous because they were created parent by parent, level by level
    child_count = np.bincount(parent_all[1:], minlength=node_count).astype(np.int64)
    child_start = np.zeros(node_count, dtype=np.int64)
    first_child = np.full(node_count, node_count, dtype=np.int64)
    np.minimum.at(first_child, parent_all[1:], np.arange(1, node_count))
    child_start[:] = np.where(child_count > 0, first_child, 0)

    leaf_centre = np.concatenate(leaves["centre"])
    leaf_radius = np.concatenate(leaves["radius"])
    piece_count = np.concatenate(leaves["count"])
    leaf_M = np.concatenate(leaves["M"])
    leaf_g = np.concatenate(leaves["g"])
    leaf_c = np.concatenate(leaves["c"])
    leaf_o = np.concatenate(leaves["origins"])
    mask = np.arange(MAX_PIECES)[None, :] < piece_count[:, None]
    leaf_start = np.zeros(len(piece_count), dtype=np.int64)
    np.cumsum(piece_count[:-1], out=leaf_start[1:])

    # support bounding boxes, bottom-up (children have larger ids than parents)
    node_lo = np.full((node_count, 4), np.inf)
    node_hi = np.full((node_count, 4), -np.inf)
    is_leaf_node = leaf_of_node >= 0
    ln = leaf_of_node[is_leaf_node]
    node_lo[is_leaf_node] = leaf_centre[ln] - leaf_radius[ln, None]
    node_hi[is_leaf_node] = leaf_centre[ln] + leaf_radius[ln, None]
    levels = np.concatenate(nodes_level)
    for level in range(int(levels.max()), 0, -1):
        at = np.flatnonzero(levels == level)
        for a in range(4):
            np.minimum.at(node_lo[:, a], parent_all[at], node_lo[at, a])
            np.maximum.at(node_hi[:, a], parent_all[at], node_hi[at, a])

    kind = np.concatenate(leaves["kind"])
    err = np.concatenate(leaves["error"])
    stats = MPUStats(
        cells=int(total_cells),
        leaves=int(len(leaf_radius)),
        lowvariate=int(np.sum(kind == KIND_LOWVARIATE)),
        generic=int(np.sum(kind == KIND_GENERIC)),
        feature=int(np.sum(kind == KIND_FEATURE)),
        depth=int(levels.max()),
        max_leaf_error=float(err.max()) if len(err) else 0.0,
    )
    log.debug("4D MPU: %s", stats)
    return MPU4D(
        child_start=child_start,
        child_count=child_count,
        node_lo=node_lo,
        node_hi=node_hi,
        node_leaf=leaf_of_node,
        leaf_centre=leaf_centre,
        leaf_radius=leaf_radius,
        leaf_start=leaf_start,
        leaf_count=piece_count,
        leaf_op=np.concatenate(leaves["op"]),
        leaf_kind=kind,
        leaf_error=err,
        M=np.ascontiguousarray(leaf_M[mask]),
        g=np.ascontiguousarray(leaf_g[mask]),
        c=np.ascontiguousarray(leaf_c[mask]),
        origins=np.ascontiguousarray(leaf_o[mask]),
        outside=float(leaf_radius.max()),
        stats=stats,
    )
