"""Fit an animated mesh to each frame's points along its normals only.

A tracked template sits a little off each frame's surface: the tracking trades the data
against rigidity and smoothness, and a filled-in part comes from a coarser field. Moving each
vertex along its own normal to the frame's points removes that error without moving the
vertex along the surface, so the correspondences the tracking found stay as they are.

Per frame and vertex ``v`` with unit normal ``n`` (from the current mesh), the points ``p``
within ``2 * radius`` of ``v`` are written in the vertex's frame, ``p - v = u e1 + w e2 + d n``,
and the height ``d`` is fitted by weighted least squares with a quadric
``d = a + b u + c w + e u^2 + f u w + g w^2`` (Gaussian weights ``exp(-(u^2+w^2)/radius^2)``).
The offset of the vertex is ``a``: a quadric, not a plane, so a curved surface is not pulled
to its chord (a plane's bias is ``curvature * radius^2 / 4``). The fit is robust: points more
than ``reach`` off the tangent plane are ignored, and each point is weighted by its distance to
the current estimate (first the vertex itself, then the first fit: two mean-shift steps), so an
outlier or the other side of a thin part does not pull. The offsets are then smoothed over the mesh (a screened Laplace problem whose
data weight is each vertex's support; vertices without points get the harmonic continuation
of their neighbours' offsets, so a filled-in region follows its rim), filtered in time with
the [1, 2, 1] kernel, capped at ``reach`` and applied; the whole is repeated ``iterations``
times with the new normals.

References
----------
Levin: Mesh-independent surface interpolation, Geometric Modeling for Scientific
Visualization, 2003 (the moving least-squares projection: a local reference plane and a
polynomial height over it, section 3).
Alexa, Behr, Cohen-Or, Fleishman, Levin, Silva: Computing and rendering point set surfaces,
IEEE TVCG 9(1), 2003 (the same projection for point sets, section 3).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from fourd.geometry.laplacian import uniform_laplacian
from fourd.geometry.normals import vertex_normals

__all__ = ["SurfaceFit", "fit_along_normals", "normal_offsets"]

#: A vertex whose Gaussian weights sum to less than this has no support from the frame.
MIN_SUPPORT = 3.0


class SurfaceFit(NamedTuple):
    """The result of :func:`fit_along_normals`.

    vertices : float64 [T, N, 3]
        The fitted vertex positions.
    offsets : float64 [T, N]
        The total displacement of each vertex along its normal (signed, in input units).
    supported : bool [T, N]
        Whether the frame had points near the vertex (its offset was fitted, not continued).
    """

    vertices: np.ndarray
    offsets: np.ndarray
    supported: np.ndarray


def _tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors [N, 3] orthogonal to each unit normal [N, 3] and to each other."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normals, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(normals, e1)


def normal_offsets(
    vertices: np.ndarray,
    normals: np.ndarray,
    points: np.ndarray,
    *,
    radius: float,
    reach: float,
    tree: cKDTree | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex, the signed distance along its normal to the quadric fitted to the points.

    Parameters
    ----------
    vertices, normals : float64 [N, 3]
        Positions and unit normals.
    points : float64 [P, 3]
        The frame's points.
    radius : float
        Width of the Gaussian weights along the surface (input units).
    reach : float or float64 [N]
        Points farther than this from a vertex's tangent plane are ignored (one value, or
        one per vertex); the offset is capped at it.

    Returns
    -------
    offsets : float64 [N]
        The fitted height of the surface above each vertex (0 where unsupported).
    support : float64 [N]
        The sum of the weights (0 where no point is near).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> plane = np.c_[rng.uniform(-1, 1, (4000, 2)), np.full(4000, 0.05)]
    >>> offsets, support = normal_offsets(np.zeros((1, 3)), np.array([[0.0, 0, 1]]), plane,
    ...                                   radius=0.1, reach=0.2)
    >>> round(float(offsets[0]), 6), bool(support[0] > 10)
    (0.05, True)
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    tree = cKDTree(points) if tree is None else tree
    n = len(vertices)
    reach = np.broadcast_to(np.asarray(reach, dtype=np.float64), (n,))
    offsets, support = np.zeros(n), np.zeros(n)
    if n == 0 or tree.n == 0:
        return offsets, support
    pairs = cKDTree(vertices).sparse_distance_matrix(tree, 2.0 * radius, output_type="ndarray")
    if len(pairs) == 0:
        return offsets, support
    rows, cols = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    e1, e2 = _tangent_frames(normals)
    height, support = _mean_shift_quadrics(
        rows, cols, vertices, normals, e1, e2, np.asarray(points, dtype=np.float64),
        np.ascontiguousarray(reach), float(radius),
    )
    ok = support >= MIN_SUPPORT
    offsets[ok] = np.clip(height[ok], -reach[ok], reach[ok])
    return offsets, np.where(ok, support, 0.0)


@numba.njit(cache=True)
def _mean_shift_quadrics(rows, cols, vertices, normals, e1, e2, points, reach, radius):
    """Per vertex, the height ``a`` of the weighted quadric fit of its points (pairs
    ``rows``, ``cols``) and the sum of the weights, after two mean-shift steps (see
    :func:`normal_offsets`); ([N], [N]), 0 where the support is under :data:`MIN_SUPPORT`."""
    n, count = len(vertices), len(rows)
    u, w, d, spread = np.empty(count), np.empty(count), np.empty(count), np.empty(count)
    for p in range(count):
        r, c = rows[p], cols[p]
        dx = points[c, 0] - vertices[r, 0]
        dy = points[c, 1] - vertices[r, 1]
        dz = points[c, 2] - vertices[r, 2]
        u[p] = (dx * e1[r, 0] + dy * e1[r, 1] + dz * e1[r, 2]) / radius
        w[p] = (dx * e2[r, 0] + dy * e2[r, 1] + dz * e2[r, 2]) / radius
        d[p] = dx * normals[r, 0] + dy * normals[r, 1] + dz * normals[r, 2]
        spread[p] = np.exp(-(u[p] * u[p] + w[p] * w[p])) if abs(d[p]) <= reach[r] else 0.0
    height, support = np.zeros(n), np.zeros(n)
    basis = np.empty(6)
    for _ in range(2):  # mean shift: points far from the last fit (first: the vertex) count less
        normal, rhs = np.zeros((n, 6, 6)), np.zeros((n, 6))
        support[:] = 0.0
        for p in range(count):
            r = rows[p]
            scale = max(reach[r] / 3.0, 1e-12)
            shift = (d[p] - height[r]) / scale
            weight = spread[p] * np.exp(-shift * shift)
            support[r] += weight
            basis[0], basis[1], basis[2] = 1.0, u[p], w[p]
            basis[3], basis[4], basis[5] = u[p] * u[p], u[p] * w[p], w[p] * w[p]
            for i in range(6):
                rhs[r, i] += weight * basis[i] * d[p]
                for j in range(i, 6):
                    normal[r, i, j] += weight * basis[i] * basis[j]
        for r in range(n):
            if support[r] < MIN_SUPPORT:
                height[r] = 0.0
                continue
            system = normal[r]
            for i in range(6):
                for j in range(i):
                    system[i, j] = system[j, i]
            # a small ridge on the slope and curvature terms keeps sparse neighbourhoods solvable
            ridge = 1e-3 * max(system[0, 0], 1e-12)
            for i in range(1, 6):
                system[i, i] += ridge
            system[0, 0] += 1e-12
            height[r] = _first_of_solution(system, rhs[r])
    return height, support


@numba.njit(cache=True, inline="always")
def _first_of_solution(system, rhs) -> float:
    """``x[0]`` of ``system @ x = rhs`` for a small symmetric positive definite ``system``
    (overwritten), by Cholesky: ``system = L L^T``, then the two triangular solves."""
    k = len(rhs)
    for j in range(k):
        total = system[j, j]
        for m in range(j):
            total -= system[j, m] * system[j, m]
        pivot = np.sqrt(max(total, 1e-300))
        system[j, j] = pivot
        for i in range(j + 1, k):
            total = system[i, j]
            for m in range(j):
                total -= system[i, m] * system[j, m]
            system[i, j] = total / pivot
    y = np.empty(k)
    for i in range(k):
        total = rhs[i]
        for m in range(i):
            total -= system[i, m] * y[m]
        y[i] = total / system[i, i]
    for i in range(k - 1, -1, -1):
        total = y[i]
        for m in range(i + 1, k):
            total -= system[m, i] * y[m]
        y[i] = total / system[i, i]
    return y[0]


def _smooth_offsets(laplacian, offsets, support, smoothness) -> np.ndarray:
    """Screened Laplace smoothing of one frame's offsets [N], data-weighted by support."""
    confidence = np.minimum(support / (4.0 * MIN_SUPPORT), 1.0)
    system = sp.diags(confidence + 1e-6) + smoothness * laplacian
    return spla.spsolve(system.tocsc(), confidence * offsets)


def _temporal_filter(offsets: np.ndarray) -> np.ndarray:
    """The [1, 2, 1] / 4 filter along the first axis, the ends weighted [2, 1] / 3."""
    if len(offsets) < 3:
        return offsets
    out = offsets.copy()
    out[1:-1] = 0.25 * offsets[:-2] + 0.5 * offsets[1:-1] + 0.25 * offsets[2:]
    out[0] = (2 * offsets[0] + offsets[1]) / 3
    out[-1] = (2 * offsets[-1] + offsets[-2]) / 3
    return out


def fit_along_normals(
    vertices: np.ndarray,
    faces: np.ndarray,
    frames: list[np.ndarray],
    *,
    radius: float,
    reach: float,
    smoothness: float = 1.0,
    iterations: int = 2,
) -> SurfaceFit:
    """Move every vertex of every frame along its normal onto that frame's points.

    Parameters
    ----------
    vertices : float64 [T, N, 3]
        The animated mesh's positions.
    faces : int [F, 3]
        Its triangles (consistently oriented).
    frames : list of float64 [P_t, 3]
        Each frame's points (outliers removed), T of them.
    radius : float
        See :func:`normal_offsets` (input units).
    reach : float or float64 [N]
        See :func:`normal_offsets`; also the cap on each step's smoothed offset.
    smoothness : float
        Weight of the mesh Laplacian against the fitted offsets (1: about a ring of
        vertices).
    iterations : int
        Fits, each with the normals of the previous one.

    Returns
    -------
    SurfaceFit
    """
    vertices = np.array(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 3 or vertices.shape[2] != 3:
        raise ValueError(f"vertices must have shape [T, N, 3], got {list(vertices.shape)}")
    if len(frames) != len(vertices):
        raise ValueError(f"{len(frames)} frames of points for {len(vertices)} mesh frames")
    count = vertices.shape[1]
    laplacian = uniform_laplacian(count, faces)
    trees = [cKDTree(points) if len(points) else None for points in frames]
    total = np.zeros(vertices.shape[:2])
    supported = np.zeros(vertices.shape[:2], dtype=bool)
    for _ in range(iterations):
        normals = np.stack([vertex_normals(v, faces) for v in vertices])
        offsets = np.zeros(vertices.shape[:2])
        for t, (points, tree) in enumerate(zip(frames, trees, strict=True)):
            if tree is None:
                continue
            raw, support = normal_offsets(
                vertices[t], normals[t], points, radius=radius, reach=reach, tree=tree
            )
            supported[t] = support > 0
            offsets[t] = _smooth_offsets(laplacian, raw, support, smoothness)
        offsets = np.clip(_temporal_filter(offsets), -reach, reach)  # reach broadcasts over [T, N]
        vertices += offsets[..., None] * normals
        total += offsets
    return SurfaceFit(vertices, total, supported)
