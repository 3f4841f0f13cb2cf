"""Regular 3D grids around point data: bounds, grid points, and the cells near the data.

A :class:`Grid` has ``shape = (nx, ny, nz)`` grid points at ``origin + spacing * (i, j, k)``
and ``(nx-1, ny-1, nz-1)`` cells; flat indices follow C order (``numpy.ravel_multi_index``),
matching the dense arrays that :func:`fourd.geometry.marching.marching_cubes` takes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter
from scipy.spatial import cKDTree

log = logging.getLogger("fourd.geometry.grid")


@dataclass(frozen=True, eq=False)
class Grid:
    """A regular grid of points.

    Attributes
    ----------
    origin : ndarray float64 [3]
        Position of grid point ``(0, 0, 0)``.
    spacing : float
        Edge length of a (cubic) cell, input units.
    shape : tuple of 3 int
        Number of grid points along each axis (at least 2 each).
    """

    origin: np.ndarray
    spacing: float
    shape: tuple[int, int, int]

    def __post_init__(self):
        origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        if not np.isfinite(origin).all():
            raise ValueError("grid origin must be finite")
        if not (np.isfinite(self.spacing) and self.spacing > 0):
            raise ValueError(f"grid spacing must be positive, got {self.spacing}")
        shape = tuple(int(n) for n in self.shape)
        if len(shape) != 3 or min(shape) < 2:
            raise ValueError(f"grid shape needs 3 axes of at least 2 points, got {shape}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "spacing", float(self.spacing))
        object.__setattr__(self, "shape", shape)

    @property
    def cell_shape(self) -> tuple[int, int, int]:
        """Number of cells along each axis, ``shape - 1``."""
        return tuple(n - 1 for n in self.shape)

    @property
    def size(self) -> int:
        """Number of grid points."""
        return int(np.prod(self.shape))

    @property
    def upper(self) -> np.ndarray:
        """Position of the last grid point, [3]."""
        return self.origin + self.spacing * (np.array(self.shape) - 1)


def padded_bounds(points: np.ndarray, pad: float) -> np.ndarray:
    """Axis-aligned bounds of ``points`` [P, 3] grown by ``pad`` on every side; ``[2, 3]``."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"points must have shape [P, 3] with P >= 1, got {list(points.shape)}")
    if pad < 0:
        raise ValueError(f"pad must be non-negative, got {pad}")
    return np.stack([points.min(axis=0) - pad, points.max(axis=0) + pad])


def fit_grid(
    points: np.ndarray,
    cell_size: float,
    *,
    pad: float | None = None,
    pad_cells: float = 2.0,
    max_size: int = 256,
) -> Grid:
    """A grid covering ``points`` with cells of ``cell_size``, padded by ``pad``.

    Parameters
    ----------
    points : ndarray [P, 3]
    cell_size : float
        Wanted cell edge (input units), typically a multiple of the point spacing.
    pad : float, optional
        Margin around the points' bounds (input units); default ``pad_cells`` cells.
    pad_cells : float
        Margin in cells when ``pad`` is not given; it grows with the cells.
    max_size : int
        Most grid points along any axis. When the data would need more, the cell size grows
        (and a margin given in cells with it) so that memory stays bounded.

    Returns
    -------
    Grid
    """
    if not (np.isfinite(cell_size) and cell_size > 0):
        raise ValueError(f"cell_size must be positive, got {cell_size}")
    if max_size < 8:
        raise ValueError(f"max_size must be at least 8, got {max_size}")
    lo, hi = padded_bounds(points, 0.0)
    extent = float((hi - lo).max())
    if pad is None:
        if pad_cells < 0:
            raise ValueError(f"pad_cells must be non-negative, got {pad_cells}")
        # ceil(extent / h + 2 * pad_cells) + 1 <= max_size
        room = max_size - 2.0 - 2.0 * pad_cells
        if room < 1.0:
            raise ValueError(
                f"max_size {max_size} leaves no room inside a margin of {pad_cells} cells"
            )
        largest = extent / room
    else:
        if pad < 0:
            raise ValueError(f"pad must be non-negative, got {pad}")
        largest = (extent + 2.0 * pad) / (max_size - 2.0)
    if cell_size < largest:
        log.debug(
            "grid cell grows from %.4g to %.4g to fit %d points per axis",
            cell_size,
            largest,
            max_size,
        )
        cell_size = largest
    margin = pad_cells * cell_size if pad is None else float(pad)
    origin = lo - margin
    shape = np.ceil((hi + margin - origin) / cell_size - 1e-9).astype(np.int64) + 1
    shape = np.clip(shape, 2, max_size)
    return Grid(origin, cell_size, tuple(int(n) for n in shape))


def grid_points(grid: Grid, indices: np.ndarray | None = None) -> np.ndarray:
    """Positions of grid points: all of them in C order ([N, 3]) or those at flat ``indices``."""
    if indices is None:
        axes = [grid.origin[a] + grid.spacing * np.arange(grid.shape[a]) for a in range(3)]
        mesh = np.meshgrid(*axes, indexing="ij")
        return np.stack([m.ravel() for m in mesh], axis=1)
    ijk = np.stack(np.unravel_index(np.asarray(indices, dtype=np.int64), grid.shape), axis=1)
    return grid.origin + grid.spacing * ijk


def cell_centres(grid: Grid, cells: np.ndarray) -> np.ndarray:
    """Centres of cells given as integer ``[M, 3]`` indices."""
    return grid.origin + grid.spacing * (np.asarray(cells, dtype=np.float64) + 0.5)


def point_cells(grid: Grid, points: np.ndarray) -> np.ndarray:
    """Integer cell index ``[P, 3]`` holding each point (clipped to the grid)."""
    cells = np.floor((np.asarray(points, dtype=np.float64) - grid.origin) / grid.spacing)
    return np.clip(cells, 0, np.array(grid.cell_shape) - 1).astype(np.int64)


def occupied_cells(grid: Grid, points: np.ndarray) -> np.ndarray:
    """Boolean ``[nx-1, ny-1, nz-1]``: cells that contain at least one of ``points``."""
    mask = np.zeros(grid.cell_shape, dtype=bool)
    if len(points):
        cells = point_cells(grid, points)
        mask[cells[:, 0], cells[:, 1], cells[:, 2]] = True
    return mask


def one_per_cube(points: np.ndarray, cell: float, priority: np.ndarray | None = None) -> np.ndarray:
    """Sorted indices ``[S]`` of ``points [P, 3]`` keeping one per cube of side ``cell`` (cubes
    at ``floor(points / cell)``): the one of highest ``priority [P]`` there, ties and no
    ``priority`` to the lowest index."""
    points = np.asarray(points, dtype=np.float64)
    if not len(points):
        return np.zeros(0, dtype=np.int64)
    order = np.arange(len(points)) if priority is None else np.argsort(-np.asarray(priority), kind="stable")
    keys = np.floor(points[order] / cell).astype(np.int64)
    keys -= keys.min(axis=0)
    extent = keys.max(axis=0) + 1
    flat = (keys[:, 0] * extent[1] + keys[:, 1]) * extent[2] + keys[:, 2]  # one int per cube
    _, first = np.unique(flat, return_index=True)
    return np.sort(order[first])


def cells_near(
    grid: Grid, points: np.ndarray, distance: float, *, tree: cKDTree | None = None
) -> np.ndarray:
    """Boolean ``[nx-1, ny-1, nz-1]``: cells whose centre lies within ``distance`` of a point.

    Cells that contain a point are always included. The candidates are the occupied cells
    dilated by ``ceil(distance / spacing)`` cells; their centres are then checked exactly.
    """
    points = np.asarray(points, dtype=np.float64)
    occupied = occupied_cells(grid, points)
    if distance <= 0 or not occupied.any():
        return occupied
    reach = int(np.ceil(distance / grid.spacing))
    candidates = maximum_filter(occupied.view(np.uint8), size=2 * reach + 1, mode="constant") > 0
    cells = np.argwhere(candidates & ~occupied)
    if len(cells):
        tree = cKDTree(points) if tree is None else tree
        nearest, _ = tree.query(
            cell_centres(grid, cells), distance_upper_bound=distance, workers=-1
        )
        near = cells[np.isfinite(nearest)]
        occupied[near[:, 0], near[:, 1], near[:, 2]] = True
    return occupied


def vertices_near(
    grid: Grid, points: np.ndarray, distance: float, *, tree: cKDTree | None = None
) -> np.ndarray:
    """Sorted flat indices of the grid points within ``distance`` of one of ``points``."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    seed = np.zeros(grid.shape, dtype=bool)
    nearest_vertex = np.clip(
        np.rint((points - grid.origin) / grid.spacing), 0, np.array(grid.shape) - 1
    ).astype(np.int64)
    seed[nearest_vertex[:, 0], nearest_vertex[:, 1], nearest_vertex[:, 2]] = True
    reach = int(np.ceil(distance / grid.spacing)) + 1
    candidates = np.flatnonzero(
        maximum_filter(seed.view(np.uint8), size=2 * reach + 1, mode="constant")
    )
    tree = cKDTree(points) if tree is None else tree
    nearest, _ = tree.query(
        grid_points(grid, candidates), distance_upper_bound=distance, workers=-1
    )
    return candidates[np.isfinite(nearest)]
