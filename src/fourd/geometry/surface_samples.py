"""Area-weighted random samples of a triangle mesh (or of a point set), with the triangle and
barycentric coordinates each came from: the metrics' surface samples
(:mod:`fourd.metrics.sampling`) and the densified frames of sparse scans
(:mod:`fourd.geometry.densify`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fourd.geometry.meshes import face_areas


class SurfaceSamples(NamedTuple):
    """Points on a triangle mesh with where they came from.

    Attributes
    ----------
    points : ndarray float64 [S, 3]
    faces : ndarray int64 [S]
        Triangle of each sample (``-1`` for samples taken from a point set without faces).
    barycentric : ndarray float64 [S, 3]
        Barycentric coordinates in that triangle (for point sets: ``[1, 0, 0]``).
    vertices : ndarray int64 [S]
        The mesh vertex nearest to each sample among its triangle's corners (for point sets:
        the index of the point itself).
    """

    points: np.ndarray
    faces: np.ndarray
    barycentric: np.ndarray
    vertices: np.ndarray


def sample_surface(
    vertices: np.ndarray, faces: np.ndarray, count: int, rng: np.random.Generator
) -> SurfaceSamples:
    """``count`` area-weighted uniform random samples of a triangle mesh.

    A mesh without faces (or whose faces all have zero area) is treated as a point set: the
    samples are ``count`` of its vertices drawn without replacement (all of them when there are
    fewer).

    Parameters
    ----------
    vertices : ndarray [N, 3]
    faces : ndarray int [F, 3]
    count : int
        Number of samples.
    rng : numpy.random.Generator
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    areas = face_areas(vertices, faces) if len(faces) else np.zeros(0)
    total = float(areas.sum())
    if len(faces) == 0 or not np.isfinite(total) or total <= 0:
        return sample_points(vertices, count, rng)
    cumulative = np.cumsum(areas)
    chosen = np.searchsorted(cumulative, rng.random(count) * cumulative[-1], side="right")
    chosen = np.minimum(chosen, len(faces) - 1)
    r1 = np.sqrt(rng.random(count))
    r2 = rng.random(count)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    corners = vertices[faces[chosen]]  # [S, 3, 3]
    points = np.einsum("sk,skd->sd", bary, corners)
    nearest = faces[chosen, np.argmax(bary, axis=1)]
    return SurfaceSamples(points, chosen.astype(np.int64), bary, nearest.astype(np.int64))


def sample_points(points: np.ndarray, count: int, rng: np.random.Generator) -> SurfaceSamples:
    """``count`` of ``points`` drawn without replacement (all when fewer), as :class:`SurfaceSamples`."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) > count:
        index = np.sort(rng.choice(len(points), count, replace=False))
    else:
        index = np.arange(len(points))
    bary = np.zeros((len(index), 3))
    bary[:, 0] = 1.0
    return SurfaceSamples(points[index], np.full(len(index), -1, dtype=np.int64), bary, index.astype(np.int64))
