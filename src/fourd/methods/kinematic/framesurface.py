"""One input frame's own surface: an implicit moving-least-squares (IMLS) distance to its
oriented points, used as the data term of the sliding (beyond the paper).

Why: the 4D implicit blends neighbouring frames, so its zero set at an input time is posed a
little behind or ahead of that frame's points (measured on ``rigid-turn``: about 2 degrees at
the first and last frames). Registering and constraining observed vertices to the frame's
own points removes that bias; the 4D implicit still fills the holes, gives the motion
between frames and the urshape.

``f(x) = sum_i w_i n_i . (x - p_i) / sum_i w_i`` over the points within ``2.5 h``,
``w_i = exp(-|x - p_i|^2 / h^2)`` (Kolluri 2008), restricted to points whose normal agrees
with the nearest point's (so the far side of a thin part does not pull); its gradient is taken
as ``sum_i w_i n_i / sum_i w_i``. ``coverage = min(1, sum_i w_i)``: 1 where the frame has
points within about ``h``, 0 far from its points. The points are bucketed in a grid of cells
of at least ``2.5 h`` (a dense index of at most ``MAX_CELLS`` cells, keyed z-fastest); every
query scans its 27 cells once, as 9 contiguous z-runs, collecting the points in range and the
nearest among them (compiled, in parallel).
"""

from __future__ import annotations

import numba
import numpy as np

from fourd.geometry.neighbors import bucket_points, cell_of

#: Points farther than this many bandwidths are ignored (their weight is below 0.2%).
CUTOFF = 2.5
#: Largest dense cell index; coarser cells beyond.
MAX_CELLS = 8_000_000


#: Queries per task of the parallel loop (each task owns one candidate buffer).
CHUNK = 256


@numba.njit(cache=True, fastmath=True)
def _exp_into(x, count, out, bits):
    """``out[:count] = exp(x[:count])`` for ``x`` in [-CUTOFF^2, 0] (the weights' exponents),
    within a relative 4e-16 of ``np.exp`` there (``bits`` [>= count] int64 scratch).
    ``2^n exp(r)`` with ``|r| <= ln 2 / 2`` by a degree-12 Taylor polynomial (remainder below
    1e-16) and ``2^n`` written as exponent bits: loops without calls or branches, which the
    compiler vectorises. The IMLS evaluation of crane's frames went 5.3 -> 4.5 ms per 10,000
    queries (the library's exp, one call per weight, had kept that loop scalar). Fast-math
    reorders ``x - n ln 2`` in two parts, so far below the range the error grows (2e-14 at
    -30)."""
    for c in range(count):
        n = np.floor(x[c] * 1.4426950408889634 + 0.5)
        r = x[c] - n * 0.6931471803691238 - n * 1.9082149292705877e-10  # ln 2, in two parts
        p = 1.0 / 479001600.0
        p = p * r + 1.0 / 39916800.0
        p = p * r + 1.0 / 3628800.0
        p = p * r + 1.0 / 362880.0
        p = p * r + 1.0 / 40320.0
        p = p * r + 1.0 / 5040.0
        p = p * r + 1.0 / 720.0
        p = p * r + 1.0 / 120.0
        p = p * r + 1.0 / 24.0
        p = p * r + 1.0 / 6.0
        p = p * r + 0.5
        p = p * r + 1.0
        out[c] = p * r + 1.0
        bits[c] = (np.int64(n) + 1023) << 52
    scale = bits.view(np.float64)
    for c in range(count):
        out[c] *= scale[c]


@numba.njit(cache=True, parallel=True)
def _imls(x, points, normals, starts, origin, cell, dims, h, capacity, out_v, out_g, out_w):
    cutoff2 = (CUTOFF * h) ** 2
    inv_h2 = 1.0 / (h * h)
    chunks = (x.shape[0] + CHUNK - 1) // CHUNK
    for chunk in numba.prange(chunks):
        candidates = np.empty(capacity + 1, np.int64)
        candidate_d2 = np.empty(capacity + 1)
        candidate_w = np.empty(capacity + 1)
        bits = np.empty(capacity + 1, np.int64)
        for q in range(chunk * CHUNK, min((chunk + 1) * CHUNK, x.shape[0])):
            x0 = x[q, 0]
            x1 = x[q, 1]
            x2 = x[q, 2]
            c0, c1, c2 = cell_of(x0, x1, x2, origin, cell)
            # cells are keyed z-fastest, so the (at most 3) cells of a z-row around the query
            # hold one contiguous run of points: 9 runs instead of 27 cells
            k0 = max(c2 - 1, 0)
            k1 = min(c2 + 1, dims[2] - 1)
            count = 0
            best = -1
            best_d2 = cutoff2
            if k0 <= k1:
                for i in range(max(c0 - 1, 0), min(c0 + 2, dims[0])):
                    gi = max(origin[0] + i * cell - x0, x0 - origin[0] - (i + 1) * cell, 0.0)
                    for j in range(max(c1 - 1, 0), min(c1 + 2, dims[1])):
                        gj = max(origin[1] + j * cell - x1, x1 - origin[1] - (j + 1) * cell, 0.0)
                        if gi * gi + gj * gj >= cutoff2:
                            continue
                        row = (i * dims[1] + j) * dims[2]
                        for p in range(starts[row + k0], starts[row + k1 + 1]):
                            d0 = x0 - points[p, 0]
                            d1 = x1 - points[p, 1]
                            d2_ = x2 - points[p, 2]
                            d2 = d0 * d0 + d1 * d1 + d2_ * d2_
                            # written always, kept when in range: no branch to mispredict
                            candidates[count] = p
                            candidate_d2[count] = d2
                            count += d2 < cutoff2
            out_v[q] = 0.0
            out_g[q, 0] = 0.0
            out_g[q, 1] = 0.0
            out_g[q, 2] = 0.0
            out_w[q] = 0.0
            for c in range(count):
                if candidate_d2[c] < best_d2:
                    best_d2 = candidate_d2[c]
                    best = candidates[c]
            if best < 0:
                continue
            # Gaussian weights of every point in range at once, then weighted sums over those
            # whose normal agrees with the nearest's
            for c in range(count):
                candidate_w[c] = -candidate_d2[c] * inv_h2
            _exp_into(candidate_w, count, candidate_w, bits)
            b0 = normals[best, 0]
            b1 = normals[best, 1]
            b2 = normals[best, 2]
            total = 0.0
            value = 0.0
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            for c in range(count):
                p = candidates[c]
                n0 = normals[p, 0]
                n1 = normals[p, 1]
                n2 = normals[p, 2]
                if n0 * b0 + n1 * b1 + n2 * b2 <= 0:
                    continue
                w = candidate_w[c]
                total += w
                value += w * (
                    n0 * (x0 - points[p, 0]) + n1 * (x1 - points[p, 1]) + n2 * (x2 - points[p, 2])
                )
                g0 += w * n0
                g1 += w * n1
                g2 += w * n2
            if total > 1e-300:
                out_v[q] = value / total
                out_g[q, 0] = g0 / total
                out_g[q, 1] = g1 / total
                out_g[q, 2] = g2 / total
            out_w[q] = min(total, 1.0)


class FrameSurface:
    """IMLS surface of one frame's oriented points.

    Parameters
    ----------
    points : ndarray [P, 3]
    normals : ndarray [P, 3]
        Unit normals, outward (negative inside, as every field of the project).
    bandwidth : float
        Gaussian width ``h`` (input units), e.g. 2 point spacings.
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, bandwidth: float):
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        if len(points) != len(normals):
            raise ValueError(f"{len(points)} points but {len(normals)} normals")
        if not bandwidth > 0:
            raise ValueError(f"bandwidth must be positive, got {bandwidth}")
        self.bandwidth = float(bandwidth)
        extent = np.ptp(points, axis=0) + 1e-12 if len(points) else np.ones(3)
        self.cell = max(CUTOFF * self.bandwidth, float(np.prod(extent) / MAX_CELLS) ** (1 / 3))
        self.origin = points.min(axis=0) if len(points) else np.zeros(3)
        self.points, order, self.starts, self.dims = bucket_points(points, self.origin, self.cell)
        self.normals = np.ascontiguousarray(normals[order])
        # the most points a query can meet: its 27 cells
        most = int(np.diff(self.starts).max()) if len(points) else 0
        self.capacity = max(1, min(len(points), 27 * most))

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """IMLS at ``x`` [M, 3]: ``(distance [M], gradient [M, 3], coverage [M])``.

        Where the frame has no point within ``2.5 h``, distance and gradient are 0 and
        coverage 0.
        """
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
        m = len(x)
        value, gradient, coverage = np.zeros(m), np.zeros((m, 3)), np.zeros(m)
        if m and len(self.points):
            _imls(
                x,
                self.points,
                self.normals,
                self.starts,
                self.origin,
                self.cell,
                self.dims,
                self.bandwidth,
                self.capacity,
                value,
                gradient,
                coverage,
            )
        return value, gradient, coverage
