"""The urshape: the template mesh extracted from a space-time implicit at one time.

000_00387fefe94cc850.txt section 4: sample ``f`` at the first time on a regular grid, run
marching cubes only in cells that have an input point inside their circumsphere (so open
scans stay open), smooth the result with a few Laplacian steps and project it back onto
``f = 0`` (the projection of section 5.1).
"""

from __future__ import annotations

import itertools
import logging

import numpy as np

from fourd.geometry.field import Field4D
from fourd.geometry.laplacian import laplacian_smooth
from fourd.geometry.marching import compact, marching_cubes
from fourd.geometry.meshes import remove_small_components

log = logging.getLogger("fourd.methods.kinematic.urshape")

#: With ``target_vertices``: marching cubes runs once more when its vertex count is off the
#: target by more than this fraction. The sliding's cost grows with the count: at the earlier
#: 0.8-1.25 crane kept 11,255 vertices for a target of 10,000 (``fourd bench``, median of 3:
#: 0.71 -> 0.59 s/frame, of which dfaust-hopping's unchanged path showed about half to be the
#: machine's drift; correspondence 0.0078 / 0.0169 -> 0.0077 / 0.0171).
VERTEX_TOLERANCE = 0.1


def data_cell_mask(points: np.ndarray, origin: np.ndarray, cell_size: float, shape) -> np.ndarray:
    """Cells (``shape`` = cells per axis) with at least one of ``points`` inside their
    circumsphere (radius ``sqrt(3)/2 * cell_size`` around the cell centre)."""
    shape = np.asarray(shape, dtype=np.int64)
    mask = np.zeros(tuple(shape), dtype=bool)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return mask
    local = (points - origin) / cell_size
    base = np.floor(local).astype(np.int64)
    radius2 = 0.75  # (sqrt(3)/2)^2 in cell units
    for offset in itertools.product((-1, 0, 1), repeat=3):
        cell = base + np.array(offset)
        centre = cell + 0.5
        d2 = np.einsum("ij,ij->i", local - centre, local - centre)
        ok = (d2 <= radius2) & np.all(cell >= 0, axis=1) & np.all(cell < shape, axis=1)
        c = cell[ok]
        mask[c[:, 0], c[:, 1], c[:, 2]] = True
    return mask


def _polygonise(field, time, bounds, cell_size, data_points, min_component_faces):
    """Marching cubes of ``f(., time)`` in ``bounds`` (cells near ``data_points`` only),
    degenerate triangles and small pieces removed; see :func:`extract_template`."""
    origin = bounds[0] - 2.0 * cell_size
    cells = np.ceil((bounds[1] - bounds[0]) / cell_size).astype(np.int64) + 4
    if np.prod(cells + 1) > 400_000_000:
        raise ValueError(f"grid of {cells.tolist()} cells is too large; raise cell_size")
    shape = cells + 1
    if data_points is not None:
        mask = data_cell_mask(data_points, origin, cell_size, cells)
        needed = np.zeros(tuple(shape), dtype=bool)
        for offset in itertools.product((0, 1), repeat=3):
            needed[
                offset[0] : offset[0] + cells[0],
                offset[1] : offset[1] + cells[1],
                offset[2] : offset[2] + cells[2],
            ] |= mask
        index = np.argwhere(needed)
    else:
        mask = None
        index = np.indices(tuple(shape)).reshape(3, -1).T
    values = np.full(tuple(shape), np.nan)
    if len(index):
        points = origin + cell_size * index
        f = field.value(points, np.full(len(points), float(time)))
        values[index[:, 0], index[:, 1], index[:, 2]] = f
    if not np.isfinite(values).any():
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    # unsampled corners are never part of a kept cell; give them the value of "outside"
    finite = np.isfinite(values)
    fill = float(np.nanmax(np.abs(values))) + 1.0
    values = np.where(finite, values, fill)
    vertices, faces = marching_cubes(values, origin=origin, spacing=cell_size, cell_mask=mask)
    if len(faces) == 0:
        return vertices, faces
    # drop degenerate triangles (marching cubes makes some with repeated corners)
    good = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    vertices, faces = compact(vertices, faces[good])
    vertices, faces = remove_small_components(vertices, faces, min_faces=min_component_faces)
    return vertices, faces


def extract_template(
    field: Field4D,
    time: float,
    *,
    bounds: np.ndarray,
    cell_size: float,
    data_points: np.ndarray | None = None,
    smoothing_iterations: int = 5,
    projection_iterations: int = 8,
    min_component_faces: int = 0,
    target_vertices: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Urshape extraction (000_00387fefe94cc850.txt section 4).

    Parameters
    ----------
    field : Field4D
        Space-time implicit, negative inside.
    time : float
        Time at which to extract.
    bounds : ndarray [2, 3]
        Box to sample (padded by two cells on every side).
    cell_size : float
        Marching-cubes cell edge length, input units.
    data_points : ndarray [P, 3], optional
        Input points at ``time``: only cells with one of them inside their circumsphere are
        polygonised (and ``f`` is only evaluated at the corners of those cells).
    smoothing_iterations : int
        Umbrella smoothing steps (step 0.5) before the projection back onto ``f = 0``.
    projection_iterations : int
        Newton steps of that projection.
    min_component_faces : int
        Connected pieces with fewer triangles are dropped (0: keep all).
    target_vertices : int
        When positive, ``cell_size`` is a first guess: if marching cubes gives more than
        :data:`VERTEX_TOLERANCE` off this many vertices, it runs once more at the cell size
        corrected by the square root of the ratio, before the smoothing and projection.

    Returns
    -------
    vertices : ndarray [N, 3]
    faces : ndarray int64 [F, 3] (outward wound; empty when ``f`` has no zero crossing)
    """
    from fourd.methods.kinematic.projection import project_to_surface

    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.shape != (2, 3) or np.any(bounds[1] < bounds[0]):
        raise ValueError(f"bounds must be [[min x, y, z], [max x, y, z]], got {bounds.tolist()}")
    if not (cell_size > 0):
        raise ValueError(f"cell_size must be positive, got {cell_size}")
    vertices, faces = _polygonise(field, time, bounds, cell_size, data_points, min_component_faces)
    ratio = len(vertices) / target_vertices if target_vertices > 0 else 1.0
    if len(faces) and abs(ratio - 1.0) > VERTEX_TOLERANCE:
        cell_size = cell_size * float(np.sqrt(ratio))
        vertices, faces = _polygonise(field, time, bounds, cell_size, data_points, min_component_faces)
    if len(faces) == 0:
        return vertices, faces
    if smoothing_iterations > 0:
        vertices = laplacian_smooth(vertices, faces, iterations=smoothing_iterations)
        vertices = project_to_surface(
            field, vertices, float(time), iterations=projection_iterations, max_step=cell_size
        )
    log.debug("urshape: %d vertices, %d faces", len(vertices), len(faces))
    return vertices, faces


#: A template at most this many vertices per point of a frame (the median frame): a template
#: denser than its data has vertices no point holds, and on sparse scans they let limbs go
#: (experiments/sparse_limbs.py: crane at 2,800 points per frame, 40 frames, correspondence
#: mean / last 0.0350 / 0.0833 with 10,000 vertices, 0.0188 / 0.0255 with 5,000, 0.0156 /
#: 0.0160 with 3,000, 0.0137 / 0.0170 with 2,000).
TEMPLATE_VERTICES_PER_POINT = 1.0


def template_size(vertices: int, points) -> int:
    """The urshape's target size: ``vertices``, or fewer on sparse frames (at most
    :data:`TEMPLATE_VERTICES_PER_POINT` per point of the median frame ``points [P_k, 3]``)."""
    median = float(np.median([len(p) for p in points])) if len(points) else 0.0
    return int(max(100, min(vertices, TEMPLATE_VERTICES_PER_POINT * median)))


def template_cell_size(points: np.ndarray, spacing: float, vertices: int) -> float:
    """Marching-cubes cell size giving about ``vertices`` urshape vertices.

    The surface area is estimated from the voxels of size ``2 * spacing`` that hold points
    (a surface crosses about 1.5 / c^2 voxels of size c per unit area, averaged over
    orientations), and marching cubes makes about 1.5 vertices per ``cell^2`` of area.
    """
    voxel = 2.0 * spacing
    keys = np.unique(np.floor(points / voxel).astype(np.int64), axis=0)
    area = len(keys) * voxel**2 / 1.5
    return float(np.sqrt(1.5 * area / vertices))
