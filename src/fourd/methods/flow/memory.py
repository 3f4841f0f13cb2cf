"""How much memory the flow method will need, estimated from the options and the data before
any of it is allocated (the up-front check of :mod:`fourd.preflight`).

The flow holds its whole space-time grid at once (every slice of :func:`~.grid.build_grid`),
so its peak grows with the cells of all slices together. Two kinds of cost make it up:

* per cell of the 4D grid, dense arrays: the labels and flags, the continuity weights
  (three per cell), the implicit fit, the solution and its starting values, the signed
  distance; and the postprocessing's upsampled field with its column map, ``refine**3``
  fine nodes per cell (:data:`CELL_BYTES` + :data:`FINE_NODE_BYTES` per fine node);
* per cell near the surface: the IRLS system over the cells still undecided (their values
  and flows to ``neighbourhood`` cells, the saddle matrices, the AMG hierarchy,
  :data:`SOLVER_BYTES`, scaled by ``(neighbourhood / 7)**2``: each flow's row of
  ``A + B^T B`` couples it to the flows of its two constraints), and the postprocessing's
  band, ``2 band + 1`` cells thick with ``refine**3`` nodes each, a sparse Laplace row and
  the CG's vectors per node (:data:`BAND_NODE_BYTES`).

Surface cells are counted from the data: the cells of a grid of at most
:data:`SURFACE_RESOLUTION` that hold at least two points (a lone outlier does not count),
scaled by the square of the resolution ratio, since a surface's cells grow with the square
of the resolution. The split between the terms comes from counting the arrays; their sum was
calibrated on the benchmark's peak resident memory at resolutions 32 and 64 (15 runs over
the ten standard scenes, ``benchmarks/BENCHMARKS.md`` at 25961df, less 300 MB for the
process and its data): the estimate is 1.0 (rigid-turn, waving-sheet) to 2.2 (crane,
dfaust-hopping) times those peaks. It leaves out
``mass_levels=true``'s finer meshes, which have measured up to twice as much at resolution
64 on squash-ball.
"""

from __future__ import annotations

import numpy as np

from fourd.errors import InputError
from fourd.methods.flow.grid import build_grid
from fourd.methods.flow.options import Options
from fourd.sequence import PointCloudSequence

__all__ = [
    "BAND_NODE_BYTES",
    "CELL_BYTES",
    "FINE_NODE_BYTES",
    "MEMORY_OPTIONS",
    "SOLVER_BYTES",
    "SURFACE_RESOLUTION",
    "estimate_peak_bytes",
]

#: Dense arrays per cell of the 4D grid (labels, weights, fit, solution, distance).
CELL_BYTES = 136
#: The postprocessing's upsampled field (float32) and column map (int32) per fine node.
FINE_NODE_BYTES = 8
#: The IRLS system per surface cell with the 7-cell neighbourhood.
SOLVER_BYTES = 8000
#: The postprocessing's band system per band node.
BAND_NODE_BYTES = 300
#: Surface cells are counted on a grid this coarse, then scaled (see the module docstring).
SURFACE_RESOLUTION = 32
#: Frames and points per frame the surface count reads (evenly spread; enough for a grid
#: of :data:`SURFACE_RESOLUTION`, and it keeps the estimate cheap on long, dense captures).
SURFACE_FRAMES = 16
SURFACE_POINTS = 50_000
#: The options the estimate grows with, the first the one to lower (named by the check).
MEMORY_OPTIONS = ("resolution", "time_substeps", "max_substeps", "neighbourhood", "refine", "band")


def estimate_peak_bytes(
    data: PointCloudSequence | np.ndarray,
    options: Options | None = None,
    *,
    frames: int | None = None,
) -> int:
    """Estimated peak memory of :func:`~.pipeline.run` beyond what the process holds already.

    Parameters
    ----------
    data : PointCloudSequence, or bounds ndarray [2, 3] (min, max corners, input units)
        The input; with bounds alone the surface is taken as half the box's surface, which
        errs high (crane's cells near data are a fifth of its box's surface, squash-ball's a
        quarter).
    options : Options, optional
    frames : int, optional
        Frames of the input, needed with bounds (default: the sequence's). With
        ``options.window`` one window's frames are solved at a time (on the whole input's
        bounds here, which errs high).

    Returns
    -------
    int
        Bytes. ``time_substeps=0`` (automatic) is counted at ``max_substeps``.

    Examples
    --------
    >>> box = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 1.0]])
    >>> coarse = estimate_peak_bytes(box, Options(resolution=32), frames=20)
    >>> fine = estimate_peak_bytes(box, Options(resolution=64), frames=20)
    >>> 0.1 < coarse / 2**30 < 2, 3 < fine / coarse < 8
    (True, True)
    """
    options = Options() if options is None else options
    if isinstance(data, PointCloudSequence):
        bounds = data.bounds()
        frames = len(data) if frames is None else frames
        points = [frame.points for frame in data.frames]
    else:
        bounds = np.asarray(data, float)
        if bounds.shape != (2, 3):
            raise InputError(f"bounds must have shape [2, 3], got {list(bounds.shape)}")
        if frames is None:
            raise InputError("frames is needed to estimate from bounds alone")
        points = None
    frames = int(frames) if not options.window else min(int(frames), options.window)
    substeps = options.time_substeps or options.max_substeps
    slices = frames if frames < 2 else (frames - 1) * max(substeps, 1) + 1
    shape = _grid_shape(bounds, options.resolution)
    cells = shape[0] * shape[1] * shape[2] * slices  # Python ints: no overflow at any resolution
    coarse = min(options.resolution, SURFACE_RESOLUTION)
    if points is None:
        x, y, z = _grid_shape(bounds, coarse)
        per_slice = (x * y + y * z + x * z) * 1.0  # half of the box's surface, in cells
    else:
        per_slice = _surface_cells(points, bounds, coarse)
    surface = per_slice * (options.resolution / coarse) ** 2 * slices
    fine = options.refine**3
    per_cell = CELL_BYTES + FINE_NODE_BYTES * fine
    per_surface = SOLVER_BYTES * (options.neighbourhood / 7) ** 2 + BAND_NODE_BYTES * fine * (
        2 * options.band + 1
    )
    return int(cells * per_cell + surface * per_surface)


def _grid_shape(bounds: np.ndarray, resolution: int) -> tuple[int, int, int]:
    """Cells per axis of :func:`~.grid.build_grid` (padding included)."""
    grid = build_grid(bounds, np.zeros(1), resolution=resolution, substeps=1)
    return tuple(int(n) for n in grid.shape)


def _surface_cells(points: list[np.ndarray], bounds: np.ndarray, resolution: int) -> float:
    """Mean over (at most :data:`SURFACE_FRAMES`) frames of the cells of a grid of
    ``resolution`` that hold at least two of the frame's points."""
    grid = build_grid(bounds, np.zeros(1), resolution=resolution, substeps=1)
    strides = np.array([grid.shape[1] * grid.shape[2], grid.shape[2], 1])
    chosen = np.unique(
        np.linspace(0, len(points) - 1, min(len(points), SURFACE_FRAMES)).astype(int)
    )
    counts = []
    for index in chosen:
        frame = points[index]
        frame = frame[:: max(1, len(frame) // SURFACE_POINTS)]
        keys = grid.cell_of(frame) @ strides
        _, hits = np.unique(keys, return_counts=True)
        counts.append(int((hits >= 2).sum()))
    return float(np.mean(counts)) if counts else 0.0
