"""One frame's points meshed on their own: the per-frame surface every mesh-based method
starts from (``perframe`` returns it, ``assembly`` assembles it).

Remove outliers (statistical, then small isolated clusters), estimate oriented normals (PCA;
consistent propagation, each connected part then turned to face the sensors when the frame has
them, else outwards), sample an implicit moving-least-squares signed distance on a grid near
the data, extract its zero set by marching cubes restricted to cells near the data (so open
scans stay open), drop tiny disconnected pieces, give each pinched vertex (two fans of faces
meeting at it only, where kept cells touch at an edge or a corner) a copy per fan, and
optionally smooth lightly (Taubin).

:func:`frame_surface` is a pure function of one frame's arrays and the settings, so frames can
be mapped over by any executor. All scales are multiples of the frame's point spacing (or of
the grid cell, when ``max_grid`` caps the grid on very dense frames).

References
----------
Hoppe, DeRose, Duchamp, McDonald, Stuetzle: Surface reconstruction from unorganized points,
SIGGRAPH 1992 (the pipeline: normals, signed distance, marching cubes, sections 3-4).
Kolluri: Provably good moving least squares, ACM Trans. Algorithms 4(2), 2008 (the implicit).
Taubin: A signal processing approach to fair surface design, SIGGRAPH 1995 (smoothing, sec. 4).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from fourd.geometry.fans import split_pinches
from fourd.geometry.grid import fit_grid
from fourd.geometry.implicit import imls_grid
from fourd.geometry.marching import compact, marching_cubes
from fourd.geometry.meshes import remove_small_components, vertex_adjacency
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.normals import estimate_normals
from fourd.geometry.outliers import remove_outliers

log = logging.getLogger("fourd.geometry.frame_surface")


@dataclass(frozen=True)
class SurfaceSettings:
    """Settings of :func:`frame_surface`. Lengths are in multiples of the frame's point spacing
    (median nearest-neighbour distance) unless noted; on frames so dense that ``max_grid`` caps
    the grid, in multiples of ``cell / grid_scale`` instead (and the points are first averaged
    per half of that length).

    Attributes
    ----------
    outlier_k : int
        Neighbours for the outlier tests.
    outlier_z : float
        A point whose mean distance to its neighbours exceeds the mean by this many standard
        deviations is an outlier.
    cluster_radius : float
        Linking distance of the isolated-cluster test (spacings).
    min_cluster_fraction : float
        Point clusters smaller than this fraction of the largest are removed.
    normals_k : int
        Neighbours for PCA normals (``normal_k`` is still accepted by ``fourd`` and
        ``make_options``, with a warning).
    orientation : {"auto", "sensors", "propagation"}
        How PCA normals get their sign. ``"propagation"``: consistent propagation over the
        neighbour graph with an outward check; ``"sensors"``: each normal faces its nearest
        sensor, then neighbours vote (:func:`fourd.geometry.normals.orient_to_sensors`);
        ``"auto"``: propagation, then each connected part takes the sign that makes more of
        its normals face a sensor (the outward check when the frame has no sensors).
    use_input_normals : bool
        Use the frame's own normals when it has them instead of estimating new ones.
    grid_scale : float
        Grid cell edge (spacings).
    max_grid : int
        Most grid points along an axis; the cell grows beyond ``grid_scale`` when needed.
    bandwidth : float
        Width of the Gaussian weights of the implicit (spacings); larger smooths more noise.
    support : float
        Points further than this from a grid point are ignored (bandwidths). Widened when needed
        so that every cell kept by ``clip_distance`` has all its corners evaluated.
    agreement : float
        Cosine threshold of the thin-part guard of the implicit (-1 turns it off).
    clip_distance : float
        Triangles are kept only where their centre lies within this distance of a cleaned
        point (spacings), so open scans stay open; holes wider than about twice this stay
        open too (unseen regions are not filled in).
    min_component_fraction : float
        Mesh components with fewer faces than this fraction of the largest are removed.
    smoothing_iterations : int
        Taubin smoothing steps (each a shrink and an inflate step); 0 for none.
    spacing : float or None
        Override the measured point spacing (input units).
    seed : int
        Seed of the point subsample used to measure the spacing.
    """

    outlier_k: int = 16
    outlier_z: float = 5.0
    cluster_radius: float = 3.0
    min_cluster_fraction: float = 0.01
    normals_k: int = 16
    orientation: Literal["auto", "sensors", "propagation"] = "auto"
    use_input_normals: bool = True
    grid_scale: float = 1.0
    max_grid: int = 256
    bandwidth: float = 2.0
    support: float = 2.0
    agreement: float = 0.0
    clip_distance: float = 2.0
    min_component_fraction: float = 0.05
    smoothing_iterations: int = 0
    spacing: float | None = None
    seed: int = 0

    def __post_init__(self):
        for name in ("outlier_k", "normals_k"):
            if getattr(self, name) < 3:
                raise ValueError(f"{name} must be at least 3, got {getattr(self, name)}")
        for name in (
            "outlier_z",
            "cluster_radius",
            "grid_scale",
            "bandwidth",
            "support",
            "clip_distance",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value}")
        for name in ("min_cluster_fraction", "min_component_fraction"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")
        if self.orientation not in ("auto", "sensors", "propagation"):
            raise ValueError(
                f"orientation must be auto, sensors or propagation, got {self.orientation!r}"
            )
        if not -1 <= self.agreement <= 1:
            raise ValueError(f"agreement must lie in [-1, 1], got {self.agreement}")
        smallest = int(np.ceil(2.0 * (self.clip_distance / self.grid_scale + 2.0))) + 8
        if self.max_grid < smallest:
            raise ValueError(
                f"max_grid must be at least {smallest} (the clip margin on both sides plus 8), "
                f"got {self.max_grid}"
            )
        if self.smoothing_iterations < 0:
            raise ValueError(f"smoothing_iterations must be >= 0, got {self.smoothing_iterations}")
        if self.spacing is not None and not (np.isfinite(self.spacing) and self.spacing > 0):
            raise ValueError(f"spacing must be positive, got {self.spacing}")


def _empty() -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)


def taubin_smooth(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    iterations: int,
    shrink: float = 0.5,
    inflate: float = -0.53,
) -> np.ndarray:
    """Taubin's lambda/mu smoothing with uniform weights; returns new vertices [N, 3].

    Boundary vertices are smoothed along with the rest (the clipped borders are ragged).
    """
    if iterations <= 0 or len(faces) == 0:
        return vertices
    adjacency = vertex_adjacency(faces, len(vertices))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    average = sp.diags(1.0 / np.maximum(degree, 1.0)) @ adjacency
    result = vertices.copy()
    for _ in range(iterations):
        for factor in (shrink, inflate):
            result = result + factor * (average @ result - result)
    return result


def voxel_average(
    points: np.ndarray, size: float, normals: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Replace the points in each cubic voxel of edge ``size`` by their mean (and the normals
    by their normalised mean); returns ``(points [M, 3], normals [M, 3] or None)``."""
    keys = np.floor((points - points.min(axis=0)) / size).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    averaged = (
        np.stack(
            [np.bincount(inverse, points[:, a], minlength=len(counts)) for a in range(3)], axis=1
        )
        / counts[:, None]
    )
    if normals is None:
        return averaged, None
    summed = np.stack(
        [np.bincount(inverse, normals[:, a], minlength=len(counts)) for a in range(3)], axis=1
    )
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    fallback = normals[np.unique(inverse, return_index=True)[1]]
    summed = np.where(length > 1e-12, summed / np.maximum(length, 1e-300), fallback)
    return averaged, summed


def oriented_normals(
    points: np.ndarray,
    *,
    k: int = 16,
    sensors: np.ndarray | None = None,
    mode: str = "auto",
) -> np.ndarray:
    """Unit normals of ``points`` [P, 3] from PCA over ``k`` neighbours, oriented by ``mode``
    (see :class:`SurfaceSettings`, ``orientation``); returns [P, 3].

    With sensors, propagation followed by a vote per connected part is more robust than
    orienting every point towards its nearest sensor: a point seen by a camera that is not
    the nearest one, or at a grazing angle, gets the wrong sign from the sensor test alone.
    """
    return estimate_normals(points, k=k, sensors=sensors, mode=mode).normals


def cell_corner_minimum(corner: np.ndarray) -> np.ndarray:
    """The smallest of each grid cell's eight corner values: ``corner`` [X, Y, Z] -> [X - 1,
    Y - 1, Z - 1], one axis at a time (the eight shifted views stacked into one array cost
    27 ms of crane's 240 ms per frame; the same values, NaN where a corner is NaN)."""
    along_x = np.minimum(corner[:-1], corner[1:])
    along_y = np.minimum(along_x[:, :-1], along_x[:, 1:])
    del along_x
    return np.minimum(along_y[:, :, :-1], along_y[:, :, 1:])


def frame_surface(
    points: np.ndarray,
    *,
    normals: np.ndarray | None = None,
    sensors: np.ndarray | None = None,
    settings: SurfaceSettings | None = None,
    time: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh one frame's points on their own (module docstring).

    Parameters
    ----------
    points : array [P, 3]
        The frame's points, input units.
    normals : array [P, 3], optional
        Their unit normals, used when ``settings.use_input_normals``.
    sensors : array [K, 3], optional
        Scanner positions, which orient estimated normals.
    settings : SurfaceSettings, optional
    time : float
        The frame's time, for the log messages only.

    Returns
    -------
    vertices : ndarray float64 [N, 3]
    faces : ndarray int64 [F, 3]
        Outward-wound triangles; empty arrays when the frame has too few points.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> p = rng.normal(size=(3000, 3)); p /= np.linalg.norm(p, axis=1, keepdims=True)
    >>> v, f = frame_surface(p)
    >>> bool(np.abs(np.linalg.norm(v, axis=1) - 1).max() < 0.05)
    True
    """
    options = SurfaceSettings() if settings is None else settings
    points = np.asarray(points, dtype=np.float64)
    minimum = max(options.outlier_k, options.normals_k) + 2
    if len(points) < minimum:
        log.warning(
            "frame at time %g has %d points (fewer than %d): empty mesh",
            time,
            len(points),
            minimum,
        )
        return _empty()
    spacing = options.spacing or point_spacing(points, seed=options.seed)

    cleaned = remove_outliers(
        points,
        k=options.outlier_k,
        z=options.outlier_z,
        cluster_radius=options.cluster_radius * spacing,
        min_cluster_fraction=options.min_cluster_fraction,
        spacing=spacing,
    )
    kept = points[cleaned.inliers]
    if len(kept) < minimum:
        log.warning(
            "frame at time %g: only %d points survive outlier removal: empty mesh",
            time,
            len(kept),
        )
        return _empty()

    input_normals = None
    if options.use_input_normals and normals is not None:
        input_normals = np.asarray(normals, dtype=np.float64)[cleaned.inliers]

    # Pad by the clip distance plus two cells; all in cells so that it grows with the cells
    # when ``max_grid`` caps the grid.
    pad_cells = options.clip_distance / options.grid_scale + 2.0
    grid = fit_grid(
        kept, options.grid_scale * spacing, pad_cells=pad_cells, max_size=options.max_grid
    )
    # Lengths scale with the point spacing, or with the cells when the grid is capped (dense
    # data): a Gaussian or clip distance narrower than a cell would punch holes.
    scale = max(spacing, grid.spacing / options.grid_scale)
    clip = options.clip_distance * scale
    bandwidth = options.bandwidth * scale
    if scale > 2.0 * spacing:
        # Much denser than the grid resolves: average the points per half-scale voxel first,
        # which bounds the cost of the normals and the implicit by the grid, not the data.
        kept, input_normals = voxel_average(kept, 0.5 * scale, input_normals)
        log.debug("dense frame: %d points averaged to %d", int(cleaned.inliers.sum()), len(kept))

    if input_normals is not None:
        normals = input_normals
    else:
        normals = oriented_normals(
            kept, k=options.normals_k, sensors=sensors, mode=options.orientation
        )

    # Every corner of a kept cell must lie within the support.
    support = max(options.support * bandwidth, clip + 1.8 * grid.spacing)
    field = imls_grid(
        kept, normals, grid, bandwidth=bandwidth, support=support, agreement=options.agreement
    )

    nearest_corner = cell_corner_minimum(field.distance)
    cell_mask = nearest_corner <= clip
    tree = cKDTree(kept)
    values = field.values  # ours: fill in place (outside the support: outside the surface)
    values[np.isnan(values)] = grid.spacing * 4.0
    vertices, faces = marching_cubes(
        values, origin=grid.origin, spacing=grid.spacing, cell_mask=cell_mask
    )
    if len(faces) > 0:
        # The cell mask is conservative (a cell's nearest corner); clip triangles exactly.
        centroid_distance, _ = tree.query(vertices[faces].mean(axis=1), workers=-1)
        vertices, faces = compact(vertices, faces[centroid_distance <= clip])
    if len(faces) == 0:
        log.warning(
            "frame at time %g: the implicit surface has no zero crossing near the data", time
        )
        return _empty()
    vertices, faces = remove_small_components(
        vertices, faces, min_fraction=options.min_component_fraction
    )
    # kept cells touching cells left out at an edge or a corner pinch the surface there
    faces, source = split_pinches(faces, len(vertices))
    vertices = vertices[source]
    vertices = taubin_smooth(vertices, faces, iterations=options.smoothing_iterations)
    log.debug(
        "frame at time %g: %d points, %d kept, spacing %.4g, grid %s cell %.4g, %d vertices %d faces",
        time,
        len(points),
        len(kept),
        spacing,
        grid.shape,
        grid.spacing,
        len(vertices),
        len(faces),
    )
    return vertices, faces


def _surface_of(settings: SurfaceSettings, frame) -> tuple[np.ndarray, np.ndarray]:
    """:func:`frame_surface` of one frame (a module-level function: it travels to workers)."""
    return frame_surface(frame.points, normals=frame.normals, sensors=frame.sensors, settings=settings,
                         time=frame.time)


def frame_surfaces(
    frames,
    settings: SurfaceSettings,
    *,
    cache_dir: str | None = None,
    stage: str = "frame-surface",
    desc: str = "frame surfaces",
    use_faces: bool = True,
    scheduler: str = "sync",
    submit=None,
):
    """Every frame's surface ``[(vertices [N, 3], faces [F, 3]), ...]`` and how many came
    from the cache: a frame's own faces when it has them and ``use_faces`` (unreferenced
    vertices dropped), else :func:`frame_surface` of its points, kept in ``cache_dir`` under
    ``stage`` so that a rerun after an interruption reuses it (``fourd reconstruct --cache``).

    ``scheduler`` (:func:`fourd.pipeline.map_frames`): ``"sync"`` makes the frames here one
    after the other, each cached as it is made; ``"processes"`` or a ``dask.distributed``
    scheduler's address makes the missing frames side by side (the same surfaces), cached when
    they come back. ``submit``, a function like :meth:`concurrent.futures.Executor.submit`
    (the caller's worker processes), makes them there instead of ``"sync"``'s here."""
    from concurrent.futures import as_completed
    from functools import partial

    from fourd.cache import StageCache, stage_key
    from fourd.geometry.marching import compact
    from fourd.pipeline import check_scheduler, map_frames
    from fourd.progress import progress

    scheduler = check_scheduler(scheduler)
    cache = StageCache(cache_dir)
    surfaces: list = [None] * len(frames)
    missing, keys, found = [], {}, 0
    for index, frame in enumerate(frames):
        if use_faces and frame.faces is not None and len(frame.faces):
            surfaces[index] = compact(np.asarray(frame.points, dtype=np.float64),
                                      np.asarray(frame.faces, dtype=np.int64))
            continue
        keys[index] = stage_key(stage, frame.points, frame.normals, frame.sensors, settings)
        stored = cache.load(stage, keys[index])
        if stored is None:
            missing.append(index)
        else:
            surfaces[index] = (stored["vertices"], stored["faces"])
            found += 1
    make = partial(_surface_of, settings)
    if scheduler == "sync" and submit is not None and missing:
        futures = {submit(make, frames[index]): index for index in missing}
        for future in progress(as_completed(futures), desc=desc, total=len(missing)):
            index = futures[future]
            surfaces[index] = future.result()
            cache.save(stage, keys[index], {"vertices": surfaces[index][0], "faces": surfaces[index][1]})
    elif scheduler == "sync":
        for index in progress(missing, desc=desc, total=len(missing)):
            surfaces[index] = make(frames[index])
            cache.save(stage, keys[index], {"vertices": surfaces[index][0], "faces": surfaces[index][1]})
    else:
        made = map_frames(make, [frames[index] for index in missing], scheduler=scheduler, desc=desc)
        for index, (vertices, faces) in zip(missing, made, strict=True):
            surfaces[index] = (vertices, faces)
            cache.save(stage, keys[index], {"vertices": vertices, "faces": faces})
    return surfaces, found
