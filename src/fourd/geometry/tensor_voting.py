"""Tensor voting at the data points: which points lie in locally smooth surface regions.

Two passes over the ``k`` nearest neighbours of every point, votes received at the data
points only (no dense grid):

1. *cross-product votes*: every pair of neighbours ``j, k`` of a point spans a triangle with
   it whose normal ``a_j x a_k`` (``a`` the unit directions to the neighbours) votes the stick
   tensor ``(a_j x a_k)(a_j x a_k)^T``, weighted by the Gaussian of both distances. The sum
   over all pairs is the adjugate of the weighted direction covariance
   ``C = sum_j w_j a_j a_j^T`` (Cauchy-Binet), so it costs one 3x3 matrix per point. Its
   largest eigenvector is the normal estimate; ``(lambda_1 - lambda_2) / lambda_1`` the
   confidence in it.
2. *surface (stick) votes*: every point casts its stick ``n n^T``, scaled by that confidence,
   to its neighbours along the osculating circle through both (the normal bent by twice the
   angle to the voter's tangent plane), decaying as ``exp(-(s / sigma)^2 - c (kappa sigma)^2)``
   with the arc length ``s`` and curvature ``kappa``; no vote beyond ``max_angle`` off the
   tangent plane. The sum is the normal direction tensor of the receiving point.

A point is kept when its normal direction tensor is elongated (second largest over largest
eigenvalue at most ``max_ratio``, the paper's 0.8) and it received a surface saliency
``lambda_1 - lambda_2`` of at least ``min_saliency`` times the median over all points. The
second test is not in the paper: a point that receives a single vote (a sparse outlier with
one neighbour in reach) has a pure stick tensor, ratio 0, so the ratio alone keeps it.

References
----------
Medioni, Lee, Tang: A computational framework for segmentation and grouping, Elsevier 2000
(tensor voting, stick votes along the osculating circle, the decay function).
Wand, Jenke, Huang, Bokeloh, Guibas, Schilling: Reconstruction of deforming geometry from
time-varying point clouds, SGP 2007, section 3.2 "Initial estimation of recoverable 3D
topology" (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fourd.geometry.neighbors import knn, point_spacing


@dataclass(frozen=True)
class TensorVotes:
    """The outcome of :func:`tensor_voting`.

    keep : bool [P]
        Points in locally smooth regions (both tests passed).
    normals : float64 [P, 3]
        Unit, unoriented: the largest eigenvector of the normal direction tensor.
    ratio : float64 [P]
        Second largest over largest eigenvalue of that tensor in [0, 1] (1 without votes).
    saliency : float64 [P]
        Surface saliency ``lambda_1 - lambda_2`` received (about the number of consistent
        neighbours within ``sigma``).
    sigma : float
        Voting scale used (input units).
    """

    keep: np.ndarray
    normals: np.ndarray
    ratio: np.ndarray
    saliency: np.ndarray
    sigma: float


def tensor_voting(
    points: np.ndarray,
    *,
    spacing: float | None = None,
    scale: float = 3.0,
    k: int = 32,
    max_ratio: float = 0.8,
    min_saliency: float = 0.2,
    max_angle: float = 45.0,
    curvature: float = 0.5,
) -> TensorVotes:
    """Cross-product then surface tensor voting at ``points``; keeps the locally smooth ones.

    Parameters
    ----------
    points : ndarray [P, 3]
    spacing : float, optional
        Point spacing (:func:`~fourd.geometry.neighbors.point_spacing`, measured if None).
    scale : float
        Voting scale ``sigma`` in point spacings (the Gaussian's width in both passes).
    k : int
        Neighbours voting for each point (they should reach about ``2 sigma``).
    max_ratio : float
        Largest second-over-largest eigenvalue ratio kept (paper: 0.8).
    min_saliency : float
        Smallest surface saliency kept, as a fraction of the median over all points.
    max_angle : float
        Degrees off the voter's tangent plane beyond which a stick vote is not cast.
    curvature : float
        Weight ``c`` of the curvature in the decay (``(kappa sigma)^2`` is 2 at 45 degrees
        and one ``sigma``).

    Returns
    -------
    TensorVotes

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> plane = np.c_[rng.uniform(-1, 1, (2000, 2)), rng.normal(0, 0.005, 2000)]
    >>> votes = tensor_voting(np.concatenate([plane, rng.uniform(-1, 1, (200, 3))]))
    >>> bool(votes.keep[:2000].mean() > 0.97 and votes.keep[2000:].mean() < 0.2)
    True
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape [P, 3], got {list(points.shape)}")
    if len(points) < 3:
        raise ValueError(f"need at least three points to vote, got {len(points)}")
    if scale <= 0 or k < 2 or not 0 < max_ratio <= 1 or min_saliency < 0:
        raise ValueError("need scale > 0, k >= 2, 0 < max_ratio <= 1 and min_saliency >= 0")
    if not 0 < max_angle < 90 or curvature < 0:
        raise ValueError("need 0 < max_angle < 90 degrees and curvature >= 0")
    if spacing is None:
        spacing = point_spacing(points)
    sigma = float(scale) * float(spacing)
    distances, indices = knn(points, k)
    weights = np.exp(-((distances / sigma) ** 2))
    # from voter (the neighbour) to receiver (the point)
    offsets = points[:, None, :] - points[indices]
    safe = np.where(distances > 0, distances, 1.0)[..., None]
    directions = np.where(distances[..., None] > 0, offsets / safe, 0.0)

    covariance = np.einsum("pk,pka,pkb->pab", weights, directions, directions)
    normals, confidence = _stick(_adjugate(covariance))

    sin = np.einsum("pka,pka->pk", directions, normals[indices])
    sin = np.clip(sin, -1.0, 1.0)
    theta = np.arcsin(sin)
    cos = np.sqrt(1.0 - sin**2)
    tangents = directions - sin[..., None] * normals[indices]
    tangents /= np.maximum(cos, 1e-300)[..., None]
    arc = distances * np.where(np.abs(sin) > 1e-12, theta / np.where(sin == 0, 1.0, sin), 1.0)
    bend = 2.0 * sin * sigma / np.where(distances > 0, distances, np.inf)
    decay = np.exp(-((arc / sigma) ** 2) - curvature * bend**2)
    strength = confidence[indices] * decay * (np.abs(theta) <= np.radians(max_angle))
    voted = (
        np.cos(2 * theta)[..., None] * normals[indices] - np.sin(2 * theta)[..., None] * tangents
    )
    tensor = np.einsum("pk,pka,pkb->pab", strength, voted, voted)

    values, vectors = np.linalg.eigh(tensor)
    largest = values[:, 2]
    ratio = np.where(largest > 0, values[:, 1] / np.where(largest > 0, largest, 1.0), 1.0)
    saliency = largest - values[:, 1]
    floor = float(min_saliency) * float(np.median(saliency))
    keep = (ratio <= max_ratio) & (saliency >= floor) & (largest > 0)
    return TensorVotes(keep, vectors[:, :, 2], ratio, saliency, sigma)


def _adjugate(matrices: np.ndarray) -> np.ndarray:
    """Adjugates of symmetric 3x3 ``matrices`` [P, 3, 3]: rows ``c1 x c2, c2 x c0, c0 x c1``
    of the columns ``c``; the sum of the cross-product votes of all neighbour pairs."""
    c0, c1, c2 = matrices[:, :, 0], matrices[:, :, 1], matrices[:, :, 2]
    return np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)


def _stick(tensors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest eigenvector [P, 3] of each symmetric tensor [P, 3, 3] and the confidence
    ``(lambda_1 - lambda_2) / lambda_1`` [P] in it (0 for a zero tensor)."""
    values, vectors = np.linalg.eigh(tensors)
    largest = values[:, 2]
    confidence = np.where(
        largest > 0, (largest - values[:, 1]) / np.where(largest > 0, largest, 1.0), 0.0
    )
    return vectors[:, :, 2], np.clip(confidence, 0.0, 1.0)
