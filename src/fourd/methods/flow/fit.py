"""The low-resolution smooth 4D implicit fit of the preprocessing (paper 002, section 4(a)).

The paper runs the FEM reconstruction of Sharf et al. 2007 on the data points and the
inside/outside labels. Here the same role is played by a screened-membrane least-squares fit
on the flow grid itself (cell-centred values, trilinear interpolation between them):

    minimise   sum_points  w_p f(p, t)^2                      (data on the zero set)
             + sum_points  w_o (f(p - d n_p, t) + 1/2)^2       (offset points, with normals)
             + sum_seeds   w_s (f_c + 1)^2                     (inside labels at -1)
             + sum_{space faces} (f_a - f_b)^2
             + tau * sum_{time edges} (f_c^t - f_c^{t+1})^2    (4D smoothness)

with carved (outside) cells as Dirichlet values ``f = +1``. It is smooth, uses both the data and
the labels, is negative inside and positive outside, and costs one sparse SPD solve (CG with a
Jacobi preconditioner). Its two uses are the paper's: improving the labels
(local minima well below zero -> inside, local maxima well above zero -> outside) and orienting
the data normals (PCA directions, signs from the fit's gradient).

The offset points (Carr et al. 2001), ``d`` one cell in along each point's normal (oriented
by propagation and the sensors, :func:`fourd.geometry.normals.estimate_normals`), hold the
fit negative inside a thick object. Without them the interior is only pulled to -1 at the
few seeds, and where the scans leave the surface open (3 cameras miss top and bottom) the
carved cells' +1 leaks in: at resolution 64 the median fit over the cells more than 2 cells
inside the truth was +0.05 to +0.09 on ``squash-ball`` (none negative), so no interior cell
was labelled and the flow came out hollow. With them it is -0.29 to -0.34 (86-99% negative,
60-69% labelled; ``splitting-blob`` 88-100% negative).

The fit stays on the flow's grid even at resolution 64. On a grid twice as coarse,
interpolated back (the paper's "low-resolution" fit), ``dfaust-hopping`` at 64 took 2.4
instead of about 5 s for the fit, but its Chamfer went 0.0037 -> 0.0042 (scratch runs, 20k
samples, commit 4512ce4): fewer cells came out labelled outside.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy import ndimage

from fourd.methods.flow.grid import SpaceTimeGrid
from fourd.methods.flow.krylov import jacobi_cg

log = logging.getLogger("fourd.methods.flow.fit")


def trilinear(grid: SpaceTimeGrid, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trilinear interpolation stencil between cell centres.

    Returns
    -------
    index : ndarray int64 [P, 8]
        Flat spatial cell indices of the 8 surrounding centres (clipped into the grid).
    weight : ndarray float64 [P, 8]
    gradient : ndarray float64 [P, 8, 3]
        Derivative of each weight with respect to the point (input units^-1).
    """
    shape = np.array(grid.shape)
    g = (np.asarray(points, float) - grid.origin) / grid.h - 0.5
    base = np.clip(np.floor(g).astype(np.int64), 0, shape - 2)
    frac = np.clip(g - base, 0.0, 1.0)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    idx = base[:, None, :] + corners[None]
    flat = (idx[..., 0] * shape[1] + idx[..., 1]) * shape[2] + idx[..., 2]
    factors = np.where(corners[None] == 1, frac[:, None, :], 1.0 - frac[:, None, :])
    weight = factors.prod(axis=2)
    sign = np.where(corners == 1, 1.0, -1.0)
    gradient = np.empty((len(g), 8, 3))
    for a in range(3):
        others = [b for b in range(3) if b != a]
        gradient[:, :, a] = (
            sign[None, :, a] * factors[:, :, others[0]] * factors[:, :, others[1]] / grid.h
        )
    return flat, weight, gradient


class ImplicitFit(NamedTuple):
    """Result of :func:`fit_implicit`.

    values : float64 [S, X, Y, Z], negative inside, +1 on carved cells.
    iterations : int, CG iterations of the solve.
    """

    values: np.ndarray
    iterations: int


def fit_implicit(
    grid: SpaceTimeGrid,
    points: list[np.ndarray | None],
    outside: np.ndarray,
    inside: np.ndarray,
    *,
    normals: list[np.ndarray | None] | None = None,
    offset: float = 1.0,
    offset_value: float = 0.5,
    offset_weight: float = 0.5,
    data_weight: float = 4.0,
    seed_weight: float = 4.0,
    time_weight: float = 1.0,
    rtol: float = 1e-6,
) -> ImplicitFit:
    """Fit the smooth 4D implicit described in the module docstring.

    Parameters
    ----------
    points : list of ndarray [P_s, 3] or None, one per slice
    outside, inside : ndarray bool [S, X, Y, Z]
        Cells labelled outside (Dirichlet +1) and inside (soft -1).
    normals : list of ndarray [P_s, 3] or None, one per slice, optional
        Outward unit normals of the points: each point then also gives an offset point
        ``offset`` cells in along its normal, at ``-offset_value`` with ``offset_weight``
        times a point's weight (inside only: an outside offset point lands in the other
        object where two touch, and the carved cells already say where outside is).
    """
    shape4 = grid.shape4
    n = int(np.prod(shape4))
    unknown = ~outside.ravel()
    col = np.full(n, -1, dtype=np.int64)
    col[unknown] = np.arange(int(unknown.sum()))
    m = int(unknown.sum())
    rows, cols, vals = [], [], []
    rhs = np.zeros(m)
    strides = np.array([np.prod(shape4[a + 1 :]) for a in range(4)], dtype=np.int64)
    flat = np.arange(n).reshape(shape4)
    for axis in range(4):
        weight = time_weight if axis == 0 else 1.0
        a = np.take(flat, np.arange(shape4[axis] - 1), axis=axis).ravel()
        b = a + strides[axis]
        ua, ub = unknown[a], unknown[b]
        both = ua & ub
        ia, ib = col[a[both]], col[b[both]]
        rows += [ia, ib, ia, ib]
        cols += [ia, ib, ib, ia]
        vals += [np.full(len(ia), weight)] * 2 + [np.full(len(ia), -weight)] * 2
        for idx in (col[a[ua & ~ub]], col[b[ub & ~ua]]):  # edges to carved cells (f = +1)
            rows.append(idx)
            cols.append(idx)
            vals.append(np.full(len(idx), weight))
            np.add.at(rhs, idx, weight * 1.0)
    # data points: point p's value is the row sum_k w_pk f(corner_pk) of a sparse stencil
    # W [P, m] (the carved corners' known +1 moved into const_p), energy pw_p (W f + const)_p^2
    # -> W^T diag(pw) W in the matrix, -W^T (pw const) on the right side
    stencil_rows, stencil_cols, stencil_weights, point_weights, point_consts = [], [], [], [], []
    first = 0
    for s, pts in enumerate(points):
        if pts is None or len(pts) == 0:
            continue
        cell = grid.cell_of(pts)
        key = (cell[:, 0] * grid.shape[1] + cell[:, 1]) * grid.shape[2] + cell[:, 2]
        _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        # the points at value 0; with normals also the offset points in, at -offset_value
        samples = [(pts, 0.0, 1.0)]  # (where, value, weight per point)
        if normals is not None and normals[s] is not None and offset > 0:
            samples.append((pts - offset * grid.h * normals[s], -offset_value, offset_weight))
        for where, target, share in samples:
            index, weight, _ = trilinear(grid, where)
            index = index + s * strides[0]
            point_weights.append(share * data_weight / counts[inverse])
            known = ~unknown[index]
            # value +1 at carved corners, moved to the right side with the target
            point_consts.append((weight * known).sum(axis=1) - target)
            point, corner = np.nonzero(~known)
            stencil_rows.append(first + point)
            stencil_cols.append(col[index[point, corner]])
            stencil_weights.append(weight[point, corner])
            first += len(pts)
    if first:
        stencil = sp.csr_matrix(
            (
                np.concatenate(stencil_weights),
                (np.concatenate(stencil_rows), np.concatenate(stencil_cols)),
            ),
            shape=(first, m),
        )
        pw = np.concatenate(point_weights)
        data_term = (stencil.T @ (sp.diags(pw) @ stencil)).tocoo()
        rows.append(data_term.row)
        cols.append(data_term.col)
        vals.append(data_term.data)
        rhs -= stencil.T @ (pw * np.concatenate(point_consts))
    seeds = np.flatnonzero(inside.ravel() & unknown)
    rows.append(col[seeds])
    cols.append(col[seeds])
    vals.append(np.full(len(seeds), seed_weight))
    np.add.at(rhs, col[seeds], -seed_weight)
    rows = np.concatenate(rows)
    cols = np.concatenate(cols)
    vals = np.concatenate(vals)
    matrix = sp.csr_matrix((vals, (rows, cols)), shape=(m, m))
    matrix = matrix + sp.identity(m, format="csr") * 1e-6
    # CG with a Jacobi preconditioner: a smoothed-aggregation hierarchy saved steps but cost
    # more in its set-up than all of them (squash-ball at resolution 64, 1.26M unknowns: SA
    # set-up 5.0 s + 6 CG steps 2.9 s; Jacobi 117 steps in 1.6 s with scipy's cg, the same
    # values within 2e-5), compiled on all cores as in the postprocessing
    solution, info, steps = jacobi_cg(matrix, rhs, np.zeros(m), rtol=rtol, maxiter=5000)
    if info != 0:
        log.warning("implicit fit: CG stopped after %d iterations without reaching %.0e", steps, rtol)
    values = np.ones(n)
    values[unknown] = solution
    log.debug("implicit fit: %d unknowns, %d CG iterations", m, steps)
    return ImplicitFit(values.reshape(shape4), steps)


def fit_labels(
    values: np.ndarray, outside: np.ndarray, *, level: float
) -> tuple[np.ndarray, np.ndarray]:
    """Labels from the fit: spatial local minima at or below ``-level`` are inside, local
    maxima at or above ``level`` outside (section 4(a)); ``[S, X, Y, Z]`` bool each."""
    footprint = np.zeros((1, 3, 3, 3), bool)
    footprint[0] = True
    low = np.where(outside, np.inf, values)
    high = np.where(outside, -np.inf, values)
    minima = (low <= ndimage.minimum_filter(low, footprint=footprint, mode="nearest")) & (
        low <= -level
    )
    maxima = (high >= ndimage.maximum_filter(high, footprint=footprint, mode="nearest")) & (
        high >= level
    )
    return minima & ~outside, maxima & ~outside


def deep_inside(values: np.ndarray, decided: np.ndarray, *, distance: float) -> np.ndarray:
    """Cells ``[S, X, Y, Z]`` where the fit ``values`` is negative and that lie at least
    ``distance`` cells (Euclidean, in space) from every ``decided`` cell (carved or data).

    The local minima of :func:`fit_labels` and the seeds leave the interior of a thick
    object free, and three capped IRLS iterations do not fill it from them (see the flow
    method's ``Options.deep_inside``). A slice without decided cells (a missing frame)
    gets none."""
    deep = np.zeros(values.shape, dtype=bool)
    for s in range(len(values)):
        if not decided[s].any():  # a slice without data (a missing frame): no distance
            continue
        far = ndimage.distance_transform_edt(~decided[s]) >= distance
        deep[s] = far & (values[s] < 0) & ~decided[s]
    return deep


def fit_gradient(grid: SpaceTimeGrid, values: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Spatial gradient of one slice's fit (``values`` [X, Y, Z]) at ``points`` [P, 3]; [P, 3]."""
    index, _, gradient = trilinear(grid, points)
    return np.einsum("pk,pka->pa", values.ravel()[index], gradient)
