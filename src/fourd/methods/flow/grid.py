"""The space-time grid of the flow method and its preprocessing (paper 002, section 4(a)).

The solution lives on a regular 4D grid: cubical cells of size ``h`` in space and *slices* in
time. Every input frame owns one slice; with ``time_substeps > 1`` empty slices are inserted
between frames (the paper's "solution grid finer than the data"), and frames listed as
missing keep their slice but contribute no data.

Preprocessing per slice:

* data cleaning: a statistical outlier filter (k-th neighbour distance) on each frame;
* :func:`carve_visual_hull`: a low-resolution visual hull from the scanner positions; a cell
  is outside when some sensor sees it as empty, i.e. along the sensor's ray through the cell
  the data lies further away than the cell (space carving with a per-sensor depth image);
* :func:`inside_seeds`: local maxima of the unsigned distance to the data that lie inside the
  hull (near the medial axis, so very likely inside).

References
----------
Sharf, Alcantara, Greif, Lewiner, Sheffer, Amenta, Cohen-Or: Space-time surface reconstruction
using incompressible flow, SIGGRAPH Asia 2008 (``002_382acf333feb7a6e.txt``), section 4(a).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

log = logging.getLogger("fourd.methods.flow.grid")


@dataclass(frozen=True, eq=False)
class SpaceTimeGrid:
    """A regular space-time grid.

    Attributes
    ----------
    origin : ndarray [3]
        Corner of cell ``(0, 0, 0)``; cell ``(i, j, k)`` has centre ``origin + h * (i+.5, j+.5, k+.5)``.
    h : float
        Cell size (input units).
    shape : tuple (X, Y, Z)
        Cells per axis.
    times : ndarray [S]
        Time of every slice (increasing).
    frame_slice : ndarray int [T]
        The slice of each input frame.
    """

    origin: np.ndarray
    h: float
    shape: tuple[int, int, int]
    times: np.ndarray
    frame_slice: np.ndarray

    @property
    def slices(self) -> int:
        return len(self.times)

    @property
    def shape4(self) -> tuple[int, int, int, int]:
        return (self.slices, *self.shape)

    def centres(self) -> np.ndarray:
        """Cell centres, ``[X, Y, Z, 3]``."""
        axes = [self.origin[a] + self.h * (np.arange(n) + 0.5) for a, n in enumerate(self.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        """Integer cell index of ``points`` [P, 3], clipped into the grid; ``[P, 3]``."""
        index = np.floor((points - self.origin) / self.h).astype(np.int64)
        return np.clip(index, 0, np.array(self.shape) - 1)


def build_grid(
    bounds: np.ndarray, frame_times: np.ndarray, *, resolution: int, substeps: int, padding: int = 3
) -> SpaceTimeGrid:
    """A grid with ``resolution`` cells along the longest side of ``bounds`` ([2, 3]) plus
    ``padding`` cells on every side, and ``substeps`` slices per frame interval."""
    lo, hi = np.asarray(bounds, float)
    extent = np.maximum(hi - lo, 1e-12)
    h = float(extent.max() / resolution)
    cells = np.ceil(extent / h - 1e-9).astype(int) + 2 * padding
    centre = (lo + hi) / 2
    origin = centre - h * cells / 2
    frame_times = np.asarray(frame_times, float)
    if substeps <= 1 or len(frame_times) < 2:
        times = frame_times.copy()
        frame_slice = np.arange(len(frame_times))
    else:
        parts = [
            np.linspace(a, b, substeps, endpoint=False)
            for a, b in zip(frame_times[:-1], frame_times[1:], strict=True)
        ]
        times = np.concatenate([*parts, frame_times[-1:]])
        frame_slice = np.arange(len(frame_times)) * substeps
    return SpaceTimeGrid(origin, h, tuple(int(c) for c in cells), times, frame_slice)


def frame_motion(frame_points, *, quantile: float = 99.0) -> np.ndarray:
    """How far the data moves between consecutive frames: for every pair of consecutive
    frames that both have points, the ``quantile`` percentile of the nearest-point distances
    from each frame's points to the other's (the larger of the two directions); ``nan`` where
    either frame has no points.

    A lower bound of the true motion (motion along the surface is invisible to it), but it
    sees the fast normal motion the flow's one-cell-per-slice speed bound cannot follow.

    Parameters
    ----------
    frame_points : T arrays [P, 3] or None

    Returns
    -------
    ndarray [T - 1], input units.
    """
    motion = np.full(max(len(frame_points) - 1, 0), np.nan)
    trees = [None if p is None or len(p) < 4 else cKDTree(p) for p in frame_points]
    for i in range(len(motion)):
        a, b = trees[i], trees[i + 1]
        if a is None or b is None:
            continue
        there = b.query(a.data, workers=-1)[0]
        back = a.query(b.data, workers=-1)[0]
        motion[i] = max(np.percentile(there, quantile), np.percentile(back, quantile))
    return motion


def substeps_for_motion(motion: np.ndarray, h: float, *, limit: float, most: int) -> int:
    """Slices per frame interval so that the typical (75th percentile over frame pairs)
    motion of :func:`frame_motion` is at most ``limit`` cells per slice; between 1 and
    ``most``."""
    known = motion[np.isfinite(motion)]
    if not len(known):
        return 1
    cells = float(np.percentile(known, 75)) / h
    return int(np.clip(np.ceil(cells / limit - 1e-9), 1, most))


def _basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def carve_visual_hull(
    grid: SpaceTimeGrid,
    points: np.ndarray,
    sensors: np.ndarray,
    *,
    spacing: float,
    margin: float,
    fill_pixels: int = 2,
    rim: int | None = None,
) -> np.ndarray:
    """Cells seen as empty by at least one sensor (the complement of a low-resolution visual hull).

    For every sensor a depth image is rasterised from the frame's points with a pinhole
    projection around the sensor's view direction (towards the data centroid), storing the
    nearest range per pixel. Empty pixels next to data are filled with the smallest nearby
    depth and the image is min-filtered once, which errs towards *not* carving (only cells that
    are certainly empty are labelled). A cell is carved when it projects in front of the sensor and
    its range is smaller than the pixel's depth minus ``margin``, or when it projects onto a
    background pixel (no data along that ray).

    The filling also grows the data's outline by ``fill_pixels + 1`` pixels (about three
    cells): at a grazing view of a convex top it leaves three cells above the data uncarved.
    With ``rim`` set, only the sampling's gaps (a morphological closing of ``fill_pixels``)
    and a rim of ``rim`` pixels are filled: a tighter hull (used to trim the output, see
    ``hull_trim`` of the flow options).

    Parameters
    ----------
    points : ndarray [P, 3]
    sensors : ndarray [K, 3]
    spacing : float
        Point spacing of the frame; the pixel size is at least 2 spacings and one cell.
    margin : float
        Depth tolerance (input units), covering the cell size and the scan noise.

    Returns
    -------
    ndarray bool [X, Y, Z]
    """
    centres = grid.centres().reshape(-1, 3)
    carved = np.zeros(len(centres), dtype=bool)
    centroid = points.mean(axis=0)
    for sensor in np.asarray(sensors, float):
        axis = centroid - sensor
        distance = np.linalg.norm(axis)
        if distance <= 0:
            continue
        axis /= distance
        e1, e2 = _basis(axis)
        rel = points - sensor
        z = rel @ axis
        front = z > 1e-9
        if front.sum() < 3:
            continue
        rel, z = rel[front], z[front]
        rng = np.linalg.norm(rel, axis=1)
        u, v = rel @ e1 / z, rel @ e2 / z
        pixel = max(grid.h, 2.0 * spacing) / float(np.median(z))
        pad = fill_pixels + 2
        u0, v0 = u.min() - pad * pixel, v.min() - pad * pixel
        nu = int(np.ceil((u.max() - u0) / pixel)) + pad + 1
        nv = int(np.ceil((v.max() - v0) / pixel)) + pad + 1
        iu = np.clip(((u - u0) / pixel).astype(np.int64), 0, nu - 1)
        iv = np.clip(((v - v0) / pixel).astype(np.int64), 0, nv - 1)
        depth = np.full(nu * nv, np.inf)
        np.minimum.at(depth, iu * nv + iv, rng)
        depth = depth.reshape(nu, nv)
        # Conservative image: fill holes near data with the smallest nearby depth and take the
        # 3x3 minimum (a smaller depth carves less); pixels still empty are background.
        if rim is None:
            filled = np.ones(depth.shape, dtype=bool)
        else:  # only the sampling's gaps and a rim of ``rim`` pixels
            hit = np.isfinite(depth)
            filled = ndimage.binary_dilation(hit, iterations=rim) | ndimage.binary_closing(
                hit, iterations=fill_pixels, border_value=0
            )
        work = depth
        for _ in range(fill_pixels if rim is None else fill_pixels + rim):
            grown = ndimage.minimum_filter(work, size=3, mode="constant", cval=np.inf)
            work = np.where(np.isfinite(work) | ~filled, work, grown)
        work = ndimage.minimum_filter(work, size=3, mode="constant", cval=np.inf)
        if rim is not None:
            work[~filled] = np.inf
        # cells
        crel = centres - sensor
        cz = crel @ axis
        ahead = cz > 1e-9
        cu = np.where(ahead, crel @ e1 / np.where(ahead, cz, 1.0), 0.0)
        cv = np.where(ahead, crel @ e2 / np.where(ahead, cz, 1.0), 0.0)
        ju = np.floor((cu - u0) / pixel).astype(np.int64)
        jv = np.floor((cv - v0) / pixel).astype(np.int64)
        inside_image = (ju >= 0) & (ju < nu) & (jv >= 0) & (jv < nv)
        d = np.full(len(centres), np.inf)
        ok = ahead & inside_image
        d[ok] = work[ju[ok], jv[ok]]
        crange = np.linalg.norm(crel, axis=1)
        seen_empty = ahead & (~inside_image | ~np.isfinite(d) | (crange < d - margin))
        carved |= seen_empty
    return carved.reshape(grid.shape)


def carve_by_distance(grid: SpaceTimeGrid, points: np.ndarray, *, distance: float) -> np.ndarray:
    """Fallback without sensors: cells further than ``distance`` from the data that are
    connected to the grid border through such cells (a flood fill that cannot pass through
    holes narrower than ``2 * distance``)."""
    centres = grid.centres().reshape(-1, 3)
    d, _ = cKDTree(points).query(centres, workers=-1, distance_upper_bound=distance * 1.01)
    far = (d > distance).reshape(grid.shape)
    labels, _ = ndimage.label(far)
    border = np.zeros(grid.shape, dtype=bool)
    border[[0, -1], :, :] = border[:, [0, -1], :] = border[:, :, [0, -1]] = True
    keep = np.unique(labels[border & far])
    keep = keep[keep > 0]
    return np.isin(labels, keep)


def unsigned_distance(
    grid: SpaceTimeGrid, points: np.ndarray, where: np.ndarray | None = None
) -> np.ndarray:
    """Distance from every cell centre to the nearest point, ``[X, Y, Z]``; with ``where``
    (bool ``[X, Y, Z]``) only at those cells, ``inf`` elsewhere."""
    centres = grid.centres().reshape(-1, 3)
    where = np.ones(len(centres), dtype=bool) if where is None else where.ravel()
    distance = np.full(len(centres), np.inf)
    distance[where], _ = cKDTree(points).query(centres[where], workers=-1)
    return distance.reshape(grid.shape)


def inside_seeds(distance: np.ndarray, outside: np.ndarray, *, minimum: float) -> np.ndarray:
    """Local maxima (3x3x3) of the unsigned ``distance`` to the data, inside the hull
    (``~outside``) and at least ``minimum`` from the data; ``[X, Y, Z]`` bool."""
    masked = np.where(outside, -np.inf, distance)
    peak = ndimage.maximum_filter(masked, size=3, mode="constant", cval=-np.inf)
    return (~outside) & (masked >= peak) & (distance >= minimum)


def data_cells(grid: SpaceTimeGrid, points: np.ndarray) -> np.ndarray:
    """Cells containing at least one point, ``[X, Y, Z]`` bool."""
    cells = np.zeros(grid.shape, dtype=bool)
    index = grid.cell_of(points)
    cells[index[:, 0], index[:, 1], index[:, 2]] = True
    return cells


def speed_prune(alive: np.ndarray, *, full: bool, keep: np.ndarray | None = None) -> np.ndarray:
    """Bounded speed: a cell can hold material only if a temporally adjacent cell of the
    previous and of the next slice can (Figure 2); iterated forwards and backwards. This is
    the paper's flow back-substitution: a cell whose incoming or outgoing flow is zero is zero.

    ``alive`` is ``[S, X, Y, Z]`` bool; ``full`` selects the 27-cell neighbourhood (else 7);
    cells in ``keep`` (e.g. cells fixed to one by data) are never removed.
    """
    structure = np.ones((3, 3, 3), bool) if full else ndimage.generate_binary_structure(3, 1)
    alive = alive.copy()
    keep = np.zeros_like(alive) if keep is None else keep
    for _ in range(6):
        before = int(alive.sum())
        for t in range(1, len(alive)):
            alive[t] &= ndimage.binary_dilation(alive[t - 1], structure) | keep[t]
        for t in range(len(alive) - 2, -1, -1):
            alive[t] &= ndimage.binary_dilation(alive[t + 1], structure) | keep[t]
        if int(alive.sum()) == before:
            break
    return alive
