"""Compiled evaluation of the 4D MPU (:mod:`.mpu4d`): the partition-of-unity blend of the
leaves' quadrics by tree traversal, or, for many queries at one time, through a grid of the
leaves that meet that time slice.
"""

from __future__ import annotations

import numba
import numpy as np

from fourd.methods.kinematic.mpu_fit import (
    OP_MAX,
    OP_MIN,
    _bspline,
    _bspline_derivative,
    _piece_value,
)


@numba.njit(cache=True, parallel=True)
def _evaluate(
    queries,
    with_gradient,
    child_start,
    child_count,
    node_lo,
    node_hi,
    node_leaf,
    leaf_centre,
    leaf_radius,
    leaf_start,
    leaf_count,
    leaf_op,
    M,
    g,
    c,
    origins,
    outside,
    values,
    gradients,
    chunks,
):
    q_count = len(queries)
    for chunk in numba.prange(chunks):
        stack = np.empty(1024, dtype=np.int64)
        acc = np.empty(10)
        grad = np.empty(4)
        best = np.empty(4)
        lo_q = chunk * q_count // chunks
        hi_q = (chunk + 1) * q_count // chunks
        for qi in range(lo_q, hi_q):
            x0 = queries[qi, 0]
            x1 = queries[qi, 1]
            x2 = queries[qi, 2]
            x3 = queries[qi, 3]
            stack[0] = 0
            top = 1
            acc[:] = 0.0
            while top > 0:
                top -= 1
                node = stack[top]
                if (
                    x0 < node_lo[node, 0]
                    or x0 > node_hi[node, 0]
                    or x1 < node_lo[node, 1]
                    or x1 > node_hi[node, 1]
                    or x2 < node_lo[node, 2]
                    or x2 > node_hi[node, 2]
                    or x3 < node_lo[node, 3]
                    or x3 > node_hi[node, 3]
                ):
                    continue
                leaf = node_leaf[node]
                if leaf >= 0:
                    _add_leaf(
                        leaf, x0, x1, x2, x3, with_gradient, leaf_centre, leaf_radius,
                        leaf_start, leaf_count, leaf_op, M, g, c, origins, acc, grad, best,
                    )  # fmt: skip
                else:
                    for child in range(child_start[node], child_start[node] + child_count[node]):
                        if top < 1024:
                            stack[top] = child
                            top += 1
            _blend(acc, qi, with_gradient, outside, values, gradients)


@numba.njit(cache=True, inline="always")
def _add_leaf(
    leaf, x0, x1, x2, x3, with_gradient, leaf_centre, leaf_radius, leaf_start, leaf_count,
    leaf_op, M, g, c, origins, acc, grad, best,
):  # fmt: skip
    """Adds leaf ``leaf``'s weighted local function at ``x`` to the partition-of-unity sums
    ``acc`` [10]: weight, weighted value, weight gradient [4], weighted-value gradient [4]."""
    e0 = x0 - leaf_centre[leaf, 0]
    e1 = x1 - leaf_centre[leaf, 1]
    e2 = x2 - leaf_centre[leaf, 2]
    e3 = x3 - leaf_centre[leaf, 3]
    r = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    R = leaf_radius[leaf]
    t = 1.5 * r / R
    if t >= 1.5:
        return
    weight = _bspline(t)
    start = leaf_start[leaf]
    value = _piece_value(M, g, c, origins, start, x0, x1, x2, x3, best)
    op = leaf_op[leaf]
    for p in range(start + 1, start + leaf_count[leaf]):
        v = _piece_value(M, g, c, origins, p, x0, x1, x2, x3, grad)
        if (op == OP_MAX and v > value) or (op == OP_MIN and v < value):
            value = v
            best[:] = grad
    acc[0] += weight
    acc[1] += weight * value
    if with_gradient:
        k = _bspline_derivative(t) * 1.5 / (R * r) if r > 0 else 0.0
        acc[2] += k * e0
        acc[3] += k * e1
        acc[4] += k * e2
        acc[5] += k * e3
        acc[6] += k * e0 * value + weight * best[0]
        acc[7] += k * e1 * value + weight * best[1]
        acc[8] += k * e2 * value + weight * best[2]
        acc[9] += k * e3 * value + weight * best[3]


@numba.njit(cache=True, inline="always")
def _blend(acc, qi, with_gradient, outside, values, gradients):
    """``f = sum w f_i / sum w`` and its gradient from the sums of :func:`_add_leaf`."""
    s0 = acc[0]
    if s0 > 0.0:
        f = acc[1] / s0
        values[qi] = f
        if with_gradient:
            for a in range(4):
                gradients[qi, a] = (acc[6 + a] - f * acc[2 + a]) / s0
    else:
        values[qi] = outside
        if with_gradient:
            for a in range(4):
                gradients[qi, a] = 0.0


@numba.njit(cache=True)
def _slice_grid(leaf_centre, leaf_radius, ids, w, lo, cell, dims):
    """CSR ``(start [cells + 1], leaves)`` over a 3D grid (origin ``lo``, cell size ``cell``,
    ``dims`` cells a side) of the leaves ``ids``, each listed in every cell that the box of
    its support's cross-section at time ``w`` touches."""
    n = len(ids)
    lo_cell = np.zeros((n, 3), dtype=np.int64)
    hi_cell = np.full((n, 3), -1, dtype=np.int64)
    start = np.zeros(dims[0] * dims[1] * dims[2] + 1, dtype=np.int64)
    for m in range(n):
        leaf = ids[m]
        dw = w - leaf_centre[leaf, 3]
        r2 = leaf_radius[leaf] ** 2 - dw * dw
        if r2 <= 0.0:
            continue
        r = np.sqrt(r2)
        for a in range(3):
            lo_cell[m, a] = max(np.int64(np.floor((leaf_centre[leaf, a] - r - lo[a]) / cell)), 0)
            hi_cell[m, a] = min(
                np.int64(np.floor((leaf_centre[leaf, a] + r - lo[a]) / cell)), dims[a] - 1
            )
        for i in range(lo_cell[m, 0], hi_cell[m, 0] + 1):
            for j in range(lo_cell[m, 1], hi_cell[m, 1] + 1):
                for k in range(lo_cell[m, 2], hi_cell[m, 2] + 1):
                    start[(i * dims[1] + j) * dims[2] + k + 1] += 1
    for i in range(len(start) - 1):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    leaves = np.empty(start[-1], dtype=np.int32)
    for m in range(n):
        for i in range(lo_cell[m, 0], hi_cell[m, 0] + 1):
            for j in range(lo_cell[m, 1], hi_cell[m, 1] + 1):
                for k in range(lo_cell[m, 2], hi_cell[m, 2] + 1):
                    key = (i * dims[1] + j) * dims[2] + k
                    leaves[fill[key]] = ids[m]
                    fill[key] += 1
    return start, leaves


@numba.njit(cache=True, parallel=True)
def _evaluate_slice(
    queries, with_gradient, grid_lo, grid_cell, grid_dims, grid_offset, cell_start, cell_leaves,
    leaf_centre, leaf_radius, leaf_start, leaf_count, leaf_op, M, g, c, origins, outside, values,
    gradients, chunks,
):  # fmt: skip
    """:func:`_evaluate` for queries that share one time ``w``, from that slice's grids of
    leaves (one per size class, :func:`_slice_grid`; grid ``k``'s cells start at
    ``grid_offset[k]`` in ``cell_start``) instead of the tree."""
    q_count = len(queries)
    for chunk in numba.prange(chunks):
        acc = np.empty(10)
        grad = np.empty(4)
        best = np.empty(4)
        for qi in range(chunk * q_count // chunks, (chunk + 1) * q_count // chunks):
            x0 = queries[qi, 0]
            x1 = queries[qi, 1]
            x2 = queries[qi, 2]
            x3 = queries[qi, 3]
            acc[:] = 0.0
            for grid in range(len(grid_cell)):
                cell = grid_cell[grid]
                i = np.int64(np.floor((x0 - grid_lo[grid, 0]) / cell))
                j = np.int64(np.floor((x1 - grid_lo[grid, 1]) / cell))
                k = np.int64(np.floor((x2 - grid_lo[grid, 2]) / cell))
                dims = grid_dims[grid]
                if 0 <= i < dims[0] and 0 <= j < dims[1] and 0 <= k < dims[2]:
                    key = grid_offset[grid] + (i * dims[1] + j) * dims[2] + k
                    for e in range(cell_start[key], cell_start[key + 1]):
                        _add_leaf(
                            cell_leaves[e], x0, x1, x2, x3, with_gradient, leaf_centre,
                            leaf_radius, leaf_start, leaf_count, leaf_op, M, g, c, origins, acc,
                            grad, best,
                        )  # fmt: skip
            _blend(acc, qi, with_gradient, outside, values, gradients)
