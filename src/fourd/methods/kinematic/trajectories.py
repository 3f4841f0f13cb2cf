"""Temporal smoothing of vertex trajectories that keeps out of the shape's accelerations."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fourd.geometry.neighbors import knn
from fourd.methods.kinematic.options import SMOOTHING_NEIGHBOURS


def smooth_trajectories(
    vertices: np.ndarray,
    times: np.ndarray,
    passes: int,
    *,
    motion_threshold: float = 0.0,
    neighbours: int = SMOOTHING_NEIGHBOURS,
    reference: np.ndarray | None = None,
) -> np.ndarray:
    """``passes`` of ``x_k <- x_k + w (x_k^lin - x_k)`` over frames ``vertices`` [T, N, 3], with
    ``x_k^lin`` the linear interpolation of the neighbouring frames at ``times[k]`` (with
    ``w = 1/2`` the ``[1/4, 1/2, 1/4]`` filter for even times); the first and last frames are
    kept.

    ``motion_threshold`` 0: ``w = 1/2`` everywhere. Above 0 the filter keeps out of the
    shape's accelerations: ``w = 1/2 / (1 + (m / (c s))^2)`` with ``c = motion_threshold``,
    ``s`` the median of ``|x^lin - x|`` over all vertices and frames, and ``m`` the part of the
    deviation ``x^lin - x`` that is shared in space and in time: its mean ``a_k`` over the
    vertex's ``neighbours`` nearest vertices in the first frame, taken along itself by the mean
    of ``a_(k-1)`` and ``a_(k+1)``, ``m = min(|a_k|, max(0, a_k . mean / |a_k|))``. One
    vertex's own deviation is the frame's noise, and a whole region's deviation that reverses
    in the next frame is a one-frame jump (a tracking glitch or a bounce): both are smoothed.
    A deviation that a region keeps over consecutive frames is an acceleration (a kick), which
    the plain filter would cut off the surface. ``reference`` [N, 3]: the positions whose
    nearest vertices are the neighbourhoods instead of the first frame (a stretch of a longer
    sequence takes the sequence's first frame).
    """
    x = np.array(vertices, dtype=np.float64, copy=True)
    if passes <= 0 or len(x) < 3:
        return x
    t = np.asarray(times, dtype=np.float64)
    a = ((t[2:] - t[1:-1]) / (t[2:] - t[:-2]))[:, None, None]  # weight of the previous frame
    average = None
    if motion_threshold > 0:
        n = x.shape[1]
        k = max(min(neighbours, n), 1)
        near = np.arange(n)[:, None]  # the vertex itself and its k - 1 nearest
        if k > 1:
            near = np.hstack([near, knn(x[0] if reference is None else reference, k - 1)[1]])
        rows = np.repeat(np.arange(n), k)
        average = sp.csr_matrix(
            (np.full(rows.size, 1.0 / k), (rows, near.ravel())), shape=(n, n)
        )
    for _ in range(passes):
        deviation = a * x[:-2] + (1.0 - a) * x[2:] - x[1:-1]
        weight = 0.5
        if average is not None:
            weight = 0.5 / (1.0 + (_shared_motion(deviation, average) / motion_threshold) ** 2)
        x[1:-1] += weight * deviation
    return x


def _shared_motion(deviation: np.ndarray, average: sp.csr_matrix) -> np.ndarray:
    """``m / s`` of :func:`smooth_trajectories`, [T-2, N, 1], from the deviations [T-2, N, 3]
    and the neighbourhood averaging matrix [N, N]."""
    shared = np.stack([average @ d for d in deviation])
    size = np.maximum(np.linalg.norm(shared, axis=2), 1e-300)
    around = np.zeros_like(shared)
    count = np.zeros(len(shared))
    around[1:] += shared[:-1]
    around[:-1] += shared[1:]
    count[1:] += 1.0
    count[:-1] += 1.0
    around /= np.maximum(count, 1.0)[:, None, None]
    kept = np.maximum(np.einsum("kij,kij->ki", shared, around) / size, 0.0)
    scale = max(float(np.median(np.linalg.norm(deviation, axis=2))), 1e-300)
    return (np.minimum(size, kept) / scale)[..., None]
