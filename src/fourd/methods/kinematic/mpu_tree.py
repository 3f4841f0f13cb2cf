"""The 16-ary tree of the 4D MPU (:mod:`.mpu4d`): compiled child masks, counts and point lists
of a level's children, the Z-order of the points and ball queries as CSR lists.
"""

from __future__ import annotations

import itertools

import numba
import numpy as np
from scipy.spatial import cKDTree


@numba.njit(cache=True, inline="always")
def _child_masks(x, centre, h, r2):
    """Bit masks over the 16 children (``_CORNERS`` order: bit 3 - axis 0 ... bit 0 - axis 3,
    set = +h) of the cell at ``centre`` whose children have half size ``h``: children whose
    support ball (radius squared ``r2``) holds the 4D point ``x``, and children whose box
    (max norm) holds it. Per-axis squared offsets are summed down the 2x2x2x2 choices, and a
    partial sum beyond ``r2`` prunes its subtree."""
    d0 = x[0] - centre[0]
    d1 = x[1] - centre[1]
    d2 = x[2] - centre[2]
    d3 = x[3] - centre[3]
    ball = 0
    box = 0
    for b0 in range(2):
        s0 = (d0 - h) ** 2 if b0 else (d0 + h) ** 2
        if s0 > r2:
            continue
        i0 = (0.0 <= d0 <= 2.0 * h) if b0 else (-2.0 * h <= d0 <= 0.0)
        for b1 in range(2):
            s1 = s0 + ((d1 - h) ** 2 if b1 else (d1 + h) ** 2)
            if s1 > r2:
                continue
            i1 = i0 and ((0.0 <= d1 <= 2.0 * h) if b1 else (-2.0 * h <= d1 <= 0.0))
            for b2 in range(2):
                s2 = s1 + ((d2 - h) ** 2 if b2 else (d2 + h) ** 2)
                if s2 > r2:
                    continue
                i2 = i1 and ((0.0 <= d2 <= 2.0 * h) if b2 else (-2.0 * h <= d2 <= 0.0))
                for b3 in range(2):
                    s3 = s2 + ((d3 - h) ** 2 if b3 else (d3 + h) ** 2)
                    if s3 <= r2:
                        bit = 1 << (8 * b0 + 4 * b1 + 2 * b2 + b3)
                        ball |= bit
                        if i2 and ((0.0 <= d3 <= 2.0 * h) if b3 else (-2.0 * h <= d3 <= 0.0)):
                            box |= bit
    return ball, box


@numba.njit(cache=True, parallel=True)
def _child_counts(X, indptr, indices, parents, centres, child_half, radius, counts, inside, masks):
    """Per child (16 per parent, ``_CORNERS`` order): points of the parent's list within
    ``radius`` of the child centre (``counts``) and within its box (``inside``, max norm).
    ``masks`` [len(indices)] receives, per entry of a parent's list, the bit mask of the
    children whose support holds that point (read by :func:`_child_fill`)."""
    r2 = radius * radius
    for i in numba.prange(len(parents)):
        centre = centres[parents[i]]
        local_counts = np.zeros(16, dtype=np.int64)
        local_inside = np.zeros(16, dtype=np.int64)
        for j in range(indptr[parents[i]], indptr[parents[i] + 1]):
            ball, box = _child_masks(X[indices[j]], centre, child_half, r2)
            masks[j] = ball
            if ball:
                for ch in range(16):
                    if (ball >> ch) & 1:
                        local_counts[ch] += 1
                        if (box >> ch) & 1:
                            local_inside[ch] += 1
        for ch in range(16):
            counts[i * 16 + ch] = local_counts[ch]
            inside[i * 16 + ch] = local_inside[ch]


@numba.njit(cache=True, parallel=True)
def _child_fill(indptr, indices, parents, masks, keep, out_ptr, out):
    """Point lists of the kept children (``keep`` [parents * 16] the output slot or -1) into
    the CSR ``out_ptr`` / ``out``, from the ``masks`` of :func:`_child_counts`; each list
    keeps the parent's order."""
    for i in numba.prange(len(parents)):
        pos = np.empty(16, dtype=np.int64)
        for ch in range(16):
            slot = keep[i * 16 + ch]
            pos[ch] = out_ptr[slot] if slot >= 0 else -1
        for j in range(indptr[parents[i]], indptr[parents[i] + 1]):
            ball = masks[j]
            if ball:
                for ch in range(16):
                    if (ball >> ch) & 1 and pos[ch] >= 0:
                        out[pos[ch]] = indices[j]
                        pos[ch] += 1


def z_order(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """Order [P] of points [P, D] (D * bits <= 63) along a Z-order (Morton) curve over their
    bounding cube, ``2^bits`` cells a side."""
    lo = points.min(axis=0)
    span = max(float(np.max(points.max(axis=0) - lo)), 1e-300)
    cells = np.minimum(((points - lo) / span * (1 << bits)).astype(np.int64), (1 << bits) - 1)
    dims = points.shape[1]
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(bits):
        for axis in range(dims):
            code |= ((cells[:, axis] >> bit) & 1) << (dims * bit + axis)
    return np.argsort(code, kind="stable")


def _ball_csr(
    tree: cKDTree, centres: np.ndarray, radii: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    lists = tree.query_ball_point(centres, radii, return_sorted=False)
    lengths = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
    indptr = np.zeros(len(lists) + 1, dtype=np.int64)
    np.cumsum(lengths, out=indptr[1:])
    indices = np.fromiter(
        itertools.chain.from_iterable(lists), dtype=np.int64, count=int(indptr[-1])
    )
    return indptr, indices
