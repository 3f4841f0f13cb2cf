"""Marching cubes over a regular grid, optionally restricted to chosen cells."""

from __future__ import annotations

import numpy as np
from skimage.measure import marching_cubes as _skimage_marching_cubes


def compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop vertices no face references; returns ``(vertices, faces)`` re-indexed."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    return vertices[used], remap[faces]


def marching_cubes(
    values: np.ndarray,
    *,
    origin: np.ndarray,
    spacing: float | np.ndarray,
    level: float = 0.0,
    cell_mask: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Iso-surface ``values == level`` of a scalar field sampled on a regular grid.

    Parameters
    ----------
    values : ndarray float [nx, ny, nz]
        Field at grid points ``origin + spacing * (i, j, k)``. Negative inside by convention, so
        triangles are wound counter-clockwise seen from outside (normals point outwards).
    origin : ndarray [3]
    spacing : float or ndarray [3]
    level : float
    cell_mask : ndarray bool [nx-1, ny-1, nz-1], optional
        Keep only triangles inside cells where the mask is True (e.g. cells that contain data),
        so that open scans stay open.

    Returns
    -------
    vertices : ndarray float64 [N, 3]
    faces : ndarray int64 [F, 3]
        Empty arrays when the level is not crossed.
    """
    values = np.asarray(values, dtype=np.float64)
    spacing = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,))
    origin = np.asarray(origin, dtype=np.float64)
    finite = np.isfinite(values)
    if not finite.all():
        values = np.where(finite, values, np.nanmax(np.where(finite, values, -np.inf)) + 1.0)
    if not (values.min() < level < values.max()):
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    vertices, faces, _, _ = _skimage_marching_cubes(values, level=level, spacing=tuple(spacing))
    # skimage winds triangles counter-clockwise seen from the side of larger values, which is
    # outside for our negative-inside fields.
    faces = faces.astype(np.int64)
    vertices = vertices.astype(np.float64)
    if cell_mask is not None:
        centroids = vertices[faces].mean(axis=1)
        cells = np.floor(centroids / spacing).astype(np.int64)
        cells = np.clip(cells, 0, np.array(cell_mask.shape) - 1)
        keep = cell_mask[cells[:, 0], cells[:, 1], cells[:, 2]]
        faces = faces[keep]
        if len(faces) == 0:
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
        vertices, faces = compact(vertices, faces)
    return vertices + origin, faces
