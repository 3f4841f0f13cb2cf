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

import itertools
import logging
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import NamedTuple

import numba
import numpy as np
from scipy.spatial import cKDTree

log = logging.getLogger("fourd.methods.kinematic.mpu4d")

#: Maximum number of low-variate pieces in a feature (edge / corner) cell.
MAX_PIECES = 3
#: Shape-function kinds (diagnostics).
KIND_LOWVARIATE, KIND_GENERIC, KIND_FEATURE = 0, 1, 2
#: Boolean operations combining pieces.
OP_SINGLE, OP_MAX, OP_MIN = 0, 1, 2

#: Weight of the auxiliary-point term of the generic quadric fit relative to the data term:
#: small, so that the auxiliary points fix the sign and scale of the quadric without pulling
#: it off the data (an exact quadric is reproduced exactly).
AUX_WEIGHT = 0.01
#: Evaluations of at least this many points at one time use that time slice's leaf grid.
SLICE_MIN_QUERIES = 64
#: Time slices whose leaf grids are kept.
SLICE_CACHE = 4
#: Largest leaf grid of a time slice (cells).
SLICE_MAX_CELLS = 2_000_000

_CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=4)))  # [16, 4]


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


# --------------------------------------------------------------------------------------------
# compiled local fitting
# --------------------------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def _bspline(t):
    t = abs(t)
    if t < 0.5:
        return 0.75 - t * t
    if t < 1.5:
        return 0.5 * (1.5 - t) ** 2
    return 0.0


@numba.njit(cache=True, inline="always")
def _bspline_derivative(t):
    # t >= 0
    if t < 0.5:
        return -2.0 * t
    if t < 1.5:
        return -(1.5 - t)
    return 0.0


@numba.njit(cache=True)
def _solve_spd(A, b):
    """Solve a small symmetric positive (semi-)definite system with a relative ridge."""
    n = A.shape[0]
    trace = 0.0
    for i in range(n):
        trace += A[i, i]
    ridge = 1e-9 * trace / n + 1e-300
    B = A.copy()
    for i in range(n):
        B[i, i] += ridge
    return np.linalg.solve(B, b)


@numba.njit(cache=True)
def _tangent_frame(normal):
    """Three unit vectors orthogonal to ``normal`` and to each other: T [4, 3]."""
    T = np.zeros((4, 3))
    basis = np.zeros((4, 4))
    basis[0] = normal
    count = 1
    for axis in range(4):
        v = np.zeros(4)
        v[axis] = 1.0
        for k in range(count):
            v -= np.dot(v, basis[k]) * basis[k]
        norm = np.sqrt(np.dot(v, v))
        if norm > 1e-6:
            basis[count] = v / norm
            count += 1
            if count == 4:
                break
    for k in range(3):
        T[:, k] = basis[k + 1]
    return T


@numba.njit(cache=True)
def _quadric_eval(M, g, c, origin, x):
    """Value and gradient of ``d^T M d + g.d + c`` with ``d = x - origin``."""
    d = x - origin
    Md = M @ d
    value = np.dot(d, Md) + np.dot(g, d) + c
    grad = 2.0 * Md + g
    return value, grad


@numba.njit(cache=True)
def _fit_lowvariate(X, idx, w, normal, origin, R, M_out, g_out, c_out):
    """Weighted least squares ``h = q(u)`` over the tangent space of ``normal``; writes the world
    quadric ``f = h - q(u)`` into the outputs. Returns False when ill-posed."""
    T = _tangent_frame(normal)
    A = np.zeros((10, 10))
    rhs = np.zeros(10)
    basis = np.zeros(10)
    count = 0
    Tc = np.ascontiguousarray(T.T)
    for k in range(len(idx)):
        if w[k] <= 0.0:
            continue
        x = X[idx[k]]
        d0 = x[0] - origin[0]
        d1 = x[1] - origin[1]
        d2 = x[2] - origin[2]
        d3 = x[3] - origin[3]
        h = d0 * normal[0] + d1 * normal[1] + d2 * normal[2] + d3 * normal[3]
        u0 = (d0 * Tc[0, 0] + d1 * Tc[0, 1] + d2 * Tc[0, 2] + d3 * Tc[0, 3]) / R
        u1 = (d0 * Tc[1, 0] + d1 * Tc[1, 1] + d2 * Tc[1, 2] + d3 * Tc[1, 3]) / R
        u2 = (d0 * Tc[2, 0] + d1 * Tc[2, 1] + d2 * Tc[2, 2] + d3 * Tc[2, 3]) / R
        basis[0] = u0 * u0
        basis[1] = u1 * u1
        basis[2] = u2 * u2
        basis[3] = u0 * u1
        basis[4] = u0 * u2
        basis[5] = u1 * u2
        basis[6] = u0
        basis[7] = u1
        basis[8] = u2
        basis[9] = 1.0
        for a in range(10):
            wa = w[k] * basis[a]
            rhs[a] += wa * h
            for b in range(a, 10):
                A[a, b] += wa * basis[b]
        count += 1
    if count < 10:
        return False
    for a in range(10):
        for b in range(a):
            A[a, b] = A[b, a]
    coef = _solve_spd(A, rhs)
    Q = np.zeros((3, 3))
    Q[0, 0] = coef[0]
    Q[1, 1] = coef[1]
    Q[2, 2] = coef[2]
    Q[0, 1] = Q[1, 0] = 0.5 * coef[3]
    Q[0, 2] = Q[2, 0] = 0.5 * coef[4]
    Q[1, 2] = Q[2, 1] = 0.5 * coef[5]
    Q /= R * R
    lin = coef[6:9] / R
    M_out[:, :] = -(T @ Q @ T.T)
    g_out[:] = normal - T @ lin
    c_out[0] = -coef[9]
    return True


@numba.njit(cache=True)
def _fit_generic(X, N, idx, w, origin, R, half, M_out, g_out, c_out, corners):
    """Generic 4D quadric with auxiliary points at the cell centre and its 16 corners
    (Ohtake et al. 2003, section 3)."""
    A = np.zeros((15, 15))
    rhs = np.zeros(15)
    basis = np.zeros(15)
    wsum = 0.0
    for k in range(len(idx)):
        wsum += w[k]
    if wsum <= 0.0:
        return False
    for k in range(len(idx)):
        if w[k] <= 0.0:
            continue
        y = (X[idx[k]] - origin) / R
        _generic_basis(y, basis)
        s = w[k] / wsum
        for a in range(15):
            for b in range(15):
                A[a, b] += s * basis[a] * basis[b]
    # auxiliary points
    n_aux = 0
    aux_y = np.zeros((17, 4))
    aux_d = np.zeros(17)
    m = len(idx)
    nearest = min(6, m)
    for j in range(17):
        q = origin.copy()
        if j > 0:
            q = origin + half * corners[j - 1]
        order = np.full(nearest, -1, dtype=np.int64)
        best_d = np.full(nearest, np.inf)
        for k in range(m):
            x = X[idx[k]]
            dd = (x[0] - q[0]) ** 2 + (x[1] - q[1]) ** 2 + (x[2] - q[2]) ** 2 + (x[3] - q[3]) ** 2
            if dd < best_d[nearest - 1]:
                pos = nearest - 1
                while pos > 0 and best_d[pos - 1] > dd:
                    best_d[pos] = best_d[pos - 1]
                    order[pos] = order[pos - 1]
                    pos -= 1
                best_d[pos] = dd
                order[pos] = k
        positive = 0
        negative = 0
        total = 0.0
        for k in order:
            value = np.dot(q - X[idx[k]], N[idx[k]])
            total += value
            if value > 0:
                positive += 1
            else:
                negative += 1
        if positive == nearest or negative == nearest:
            aux_y[n_aux] = (q - origin) / R
            aux_d[n_aux] = total / nearest
            n_aux += 1
    if n_aux > 0:
        for j in range(n_aux):
            _generic_basis(aux_y[j], basis)
            s = AUX_WEIGHT / n_aux
            for a in range(15):
                rhs[a] += s * basis[a] * aux_d[j]
                for b in range(15):
                    A[a, b] += s * basis[a] * basis[b]
    else:
        return False
    coef = _solve_spd(A, rhs)
    Q = np.zeros((4, 4))
    k = 0
    for a in range(4):
        for b in range(a, 4):
            if a == b:
                Q[a, a] = coef[k]
            else:
                Q[a, b] = 0.5 * coef[k]
                Q[b, a] = 0.5 * coef[k]
            k += 1
    M_out[:, :] = Q / (R * R)
    g_out[:] = coef[10:14] / R
    c_out[0] = coef[14]
    return True


@numba.njit(cache=True, inline="always")
def _generic_basis(y, basis):
    k = 0
    for a in range(4):
        for b in range(a, 4):
            basis[k] = y[a] * y[b]
            k += 1
    for a in range(4):
        basis[10 + a] = y[a]
    basis[14] = 1.0


@numba.njit(cache=True)
def _combined_eval(M, g, c, origins, start, count, op, x):
    value, grad = _quadric_eval(M[start], g[start], c[start], origins[start], x)
    for p in range(start + 1, start + count):
        v, gr = _quadric_eval(M[p], g[p], c[p], origins[p], x)
        if (op == OP_MAX and v > value) or (op == OP_MIN and v < value):
            value = v
            grad = gr
    return value, grad


@numba.njit(cache=True, inline="always")
def _piece_value(M, g, c, origins, p, x0, x1, x2, x3, grad):
    """Value of piece ``p`` at ``x``; writes its gradient into ``grad`` (no allocation)."""
    d0 = x0 - origins[p, 0]
    d1 = x1 - origins[p, 1]
    d2 = x2 - origins[p, 2]
    d3 = x3 - origins[p, 3]
    m0 = M[p, 0, 0] * d0 + M[p, 0, 1] * d1 + M[p, 0, 2] * d2 + M[p, 0, 3] * d3
    m1 = M[p, 1, 0] * d0 + M[p, 1, 1] * d1 + M[p, 1, 2] * d2 + M[p, 1, 3] * d3
    m2 = M[p, 2, 0] * d0 + M[p, 2, 1] * d1 + M[p, 2, 2] * d2 + M[p, 2, 3] * d3
    m3 = M[p, 3, 0] * d0 + M[p, 3, 1] * d1 + M[p, 3, 2] * d2 + M[p, 3, 3] * d3
    grad[0] = 2.0 * m0 + g[p, 0]
    grad[1] = 2.0 * m1 + g[p, 1]
    grad[2] = 2.0 * m2 + g[p, 2]
    grad[3] = 2.0 * m3 + g[p, 3]
    return (
        d0 * m0
        + d1 * m1
        + d2 * m2
        + d3 * m3
        + g[p, 0] * d0
        + g[p, 1] * d1
        + g[p, 2] * d2
        + g[p, 3] * d3
        + c[p]
    )


@numba.njit(cache=True)
def _local_error(X, idx, M, g, c, origins, start, count, op, quantile):
    """The ``quantile`` of the Taubin distances ``|Q(p)| / |grad Q(p)|`` over the points
    ``X[idx]`` (1.0: their maximum, as in Ohtake et al.)."""
    m = len(idx)
    errors = np.empty(m)
    grad = np.empty(4)
    best = np.empty(4)
    for k in range(m):
        x = X[idx[k]]
        value = _piece_value(M, g, c, origins, start, x[0], x[1], x[2], x[3], best)
        for p in range(start + 1, start + count):
            v = _piece_value(M, g, c, origins, p, x[0], x[1], x[2], x[3], grad)
            if (op == OP_MAX and v > value) or (op == OP_MIN and v < value):
                value = v
                best[:] = grad
        norm = np.sqrt(best[0] ** 2 + best[1] ** 2 + best[2] ** 2 + best[3] ** 2)
        errors[k] = abs(value) / max(norm, 1e-12)
    if m == 0:
        return 0.0
    if quantile >= 1.0:
        return errors.max()
    errors.sort()
    return errors[min(m - 1, int(quantile * m))]


@numba.njit(cache=True)
def _cluster_normals(N, idx, w, epsilon_c, max_clusters):
    """LBG / k-means on the normal sphere (paper, section 3): start with one centre, split the
    cluster of largest variance, re-cluster by max dot product until the centres move less
    than 1e-3, stop when the sum of cluster variances is below ``epsilon_c``."""
    m = len(idx)
    labels = np.zeros(m, dtype=np.int64)
    centres = np.zeros((max_clusters, 4))
    mean = np.zeros(4)
    for k in range(m):
        mean += N[idx[k]]
    nm = np.sqrt(np.dot(mean, mean))
    if nm < 1e-12:
        mean[0] = 1.0
        nm = 1.0
    centres[0] = mean / nm
    k_count = 1
    variances = np.zeros(max_clusters)
    sizes = np.zeros(max_clusters)
    while True:
        variances[:] = 0.0
        sizes[:] = 0.0
        for k in range(m):
            diff = centres[labels[k]] - N[idx[k]]
            variances[labels[k]] += np.dot(diff, diff)
            sizes[labels[k]] += 1.0
        total = 0.0
        for i in range(k_count):
            if sizes[i] > 0:
                variances[i] /= sizes[i]
                total += variances[i]
        if total < epsilon_c or k_count >= max_clusters:
            break
        worst = np.argmax(variances[:k_count])
        far = -1
        far_d = -1.0
        for k in range(m):
            if labels[k] == worst:
                diff = centres[worst] - N[idx[k]]
                d = np.dot(diff, diff)
                if d > far_d:
                    far_d = d
                    far = k
        if far < 0 or far_d < 1e-12:
            break
        centres[k_count] = N[idx[far]]
        k_count += 1
        for _ in range(20):
            for k in range(m):
                best = 0
                best_dot = -2.0
                for i in range(k_count):
                    d = np.dot(N[idx[k]], centres[i])
                    if d > best_dot:
                        best_dot = d
                        best = i
                labels[k] = best
            moved = 0.0
            for i in range(k_count):
                acc = np.zeros(4)
                for k in range(m):
                    if labels[k] == i:
                        acc += N[idx[k]]
                na = np.sqrt(np.dot(acc, acc))
                if na > 1e-12:
                    acc /= na
                    diff = acc - centres[i]
                    moved = max(moved, np.sqrt(np.dot(diff, diff)))
                    centres[i] = acc
            if moved < 1e-3:
                break
    return labels, k_count, centres


@numba.njit(cache=True, parallel=True)
def _fit_cells(
    X,
    N,
    indptr,
    indices,
    centres,
    radii,
    halves,
    error_target,
    cluster_epsilon,
    cos_feature,
    corners,
    M_out,
    g_out,
    c_out,
    origin_out,
    count_out,
    op_out,
    kind_out,
    error_out,
    max_fit_points,
    feature_max_points,
    error_quantile,
):
    """Fit the local shape function of every cell (outputs ``[cells, MAX_PIECES, ...]``)."""
    cells = len(radii)
    for cell in numba.prange(cells):
        idx = indices[indptr[cell] : indptr[cell + 1]]
        if len(idx) > max_fit_points:
            idx = idx[:: (len(idx) + max_fit_points - 1) // max_fit_points]
        m = len(idx)
        o = centres[cell]
        R = radii[cell]
        w = np.zeros(m)
        mean = np.zeros(4)
        for k in range(m):
            d = X[idx[k]] - o
            w[k] = _bspline(1.5 * np.sqrt(np.dot(d, d)) / R) + 1e-6
            mean += w[k] * N[idx[k]]
        nm = np.sqrt(np.dot(mean, mean))
        min_dot = 1.0
        if nm > 1e-12 and m > 0:
            mean /= nm
            dots = np.empty(m)
            for k in range(m):
                n_k = N[idx[k]]
                dots[k] = n_k[0] * mean[0] + n_k[1] * mean[1] + n_k[2] * mean[2] + n_k[3] * mean[3]
            if error_quantile >= 1.0:
                min_dot = dots.min()
            else:
                dots.sort()
                min_dot = dots[int((1.0 - error_quantile) * m)]
        else:
            min_dot = -1.0
        M = M_out[cell]
        g = g_out[cell]
        c = c_out[cell]
        for p in range(MAX_PIECES):
            origin_out[cell, p] = o
        ok = False
        if min_dot >= 0.0:
            ok = _fit_lowvariate(X, idx, w, mean, o, R, M[0], g[0], c[0:1])
            kind_out[cell] = KIND_LOWVARIATE
        if not ok:
            ok = _fit_generic(X, N, idx, w, o, R, halves[cell], M[0], g[0], c[0:1], corners)
            kind_out[cell] = KIND_GENERIC
        if not ok:
            # a plane through the weighted centroid (always well defined)
            centroid = np.zeros(4)
            wsum = 0.0
            for k in range(m):
                centroid += w[k] * X[idx[k]]
                wsum += w[k]
            centroid /= max(wsum, 1e-300)
            nrm = mean if nm > 1e-12 else np.array([1.0, 0.0, 0.0, 0.0])
            M[0, :, :] = 0.0
            g[0, :] = nrm
            c[0] = -np.dot(centroid - o, nrm)
            kind_out[cell] = KIND_LOWVARIATE
        count_out[cell] = 1
        op_out[cell] = OP_SINGLE
        err = _local_error(
            X,
            idx,
            M_out[cell],
            g_out[cell],
            c_out[cell],
            origin_out[cell],
            0,
            1,
            OP_SINGLE,
            error_quantile,
        )
        if err > error_target and min_dot < cos_feature and 20 <= m <= feature_max_points:
            labels, k_count, centres_n = _cluster_normals(
                N, idx, w, cluster_epsilon, MAX_PIECES + 1
            )
            if 2 <= k_count <= MAX_PIECES:
                Mf = np.zeros((MAX_PIECES, 4, 4))
                gf = np.zeros((MAX_PIECES, 4))
                cf = np.zeros(MAX_PIECES)
                good = True
                for i in range(k_count):
                    sub = np.empty(m, dtype=np.int64)
                    sw = np.empty(m)
                    s = 0
                    for k in range(m):
                        if labels[k] == i:
                            sub[s] = idx[k]
                            sw[s] = w[k]
                            s += 1
                    if s < 12:
                        good = False
                        break
                    if not _fit_lowvariate(
                        X, sub[:s], sw[:s], centres_n[i], o, R, Mf[i], gf[i], cf[i : i + 1]
                    ):
                        good = False
                        break
                if good:
                    # convex edge (intersection, max) when each cluster lies inside the others'
                    votes = 0
                    for i in range(k_count):
                        for j in range(k_count):
                            if i == j:
                                continue
                            acc = 0.0
                            cnt = 0
                            for k in range(m):
                                if labels[k] == i:
                                    v, _ = _quadric_eval(Mf[j], gf[j], cf[j], o, X[idx[k]])
                                    acc += v
                                    cnt += 1
                            votes += 1 if acc / max(cnt, 1) < 0 else -1
                    op = OP_MAX if votes >= 0 else OP_MIN
                    origins = np.empty((MAX_PIECES, 4))
                    for p in range(MAX_PIECES):
                        origins[p] = o
                    err_f = _local_error(
                        X, idx, Mf, gf, cf, origins, 0, k_count, op, error_quantile
                    )
                    if err_f < err:
                        M[:, :, :] = Mf
                        g[:, :] = gf
                        c[:] = cf
                        count_out[cell] = k_count
                        op_out[cell] = op
                        kind_out[cell] = KIND_FEATURE
                        err = err_f
        error_out[cell] = err


# --------------------------------------------------------------------------------------------
# compiled evaluation
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# the tree
# --------------------------------------------------------------------------------------------


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
