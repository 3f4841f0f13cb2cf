"""Compiled local shape functions of the 4D MPU (:mod:`.mpu4d`): the quadratic B-spline
weight, the low-variate and generic 4D quadric fits, the normal clustering and Boolean
combination of feature cells, and the fit of every cell of a tree level in one kernel.
"""

from __future__ import annotations

import itertools

import numba
import numpy as np

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


_CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=4)))  # [16, 4]


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
