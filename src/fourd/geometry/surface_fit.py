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
    lists = tree.query_ball_point(vertices, 2.0 * radius, workers=-1, return_sorted=False)
    counts = np.fromiter((len(item) for item in lists), dtype=np.int64, count=n)
    offsets, support = np.zeros(n), np.zeros(n)
    if counts.sum() == 0:
        return offsets, support
    rows = np.repeat(np.arange(n), counts)
    cols = np.fromiter((j for item in lists for j in item), dtype=np.int64, count=counts.sum())
    e1, e2 = _tangent_frames(normals)
    delta = points[cols] - vertices[rows]
    u = np.einsum("ij,ij->i", delta, e1[rows])
    w = np.einsum("ij,ij->i", delta, e2[rows])
    d = np.einsum("ij,ij->i", delta, normals[rows])
    spread = np.exp(-(u * u + w * w) / radius**2) * (np.abs(d) <= reach[rows])
    basis = np.stack([np.ones_like(u), u / radius, w / radius, (u / radius) ** 2,
                      (u * w) / radius**2, (w / radius) ** 2], axis=1)
    height = np.zeros(n)
    scale = np.maximum(reach[rows] / 3.0, 1e-12)
    for _ in range(2):  # mean shift: points far from the last fit (first: the vertex) count less
        weight = spread * np.exp(-(((d - height[rows]) / scale) ** 2))
        support = np.bincount(rows, weight, minlength=n)
        height = _weighted_quadric_heights(rows, basis, d, weight, n)
        height = np.where(support >= MIN_SUPPORT, height, 0.0)
    ok = support >= MIN_SUPPORT
    offsets[ok] = np.clip(height[ok], -reach[ok], reach[ok])
    return offsets, np.where(ok, support, 0.0)


def _weighted_quadric_heights(rows, basis, d, weight, n) -> np.ndarray:
    """Per row, ``a`` of the weighted least-squares fit of ``d ~ basis @ coefficients``."""
    k = basis.shape[1]
    normal = np.zeros((n, k, k))
    rhs = np.zeros((n, k))
    for i in range(k):
        rhs[:, i] = np.bincount(rows, weight * basis[:, i] * d, minlength=n)
        for j in range(i, k):
            value = np.bincount(rows, weight * basis[:, i] * basis[:, j], minlength=n)
            normal[:, i, j] = normal[:, j, i] = value
    # a small ridge on the slope and curvature terms keeps sparse neighbourhoods solvable
    ridge = 1e-3 * np.maximum(normal[:, 0, 0], 1e-12)
    normal[:, np.arange(1, k), np.arange(1, k)] += ridge[:, None]
    normal[:, 0, 0] += 1e-12
    return np.linalg.solve(normal, rhs[..., None])[:, 0, 0]


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
