"""Per-frame preparation of the input: outlier removal and oriented normals (a pure
function of one frame and the options), each frame kept in the cache when there is one.
"""

from __future__ import annotations

import logging

import numpy as np

from fourd.cache import NO_CACHE, StageCache, report_resumed, stage_key
from fourd.geometry.densify import densify_points
from fourd.geometry.frame_surface import SurfaceSettings, frame_surface
from fourd.geometry.meshes import face_areas
from fourd.geometry.neighbors import knn, neighbours_among
from fourd.geometry.normals import estimate_normals
from fourd.geometry.outliers import distance_ratio_inliers
from fourd.methods.kinematic.options import (
    DENSIFIED_POINTS_PER_VERTEX,
    OUTLIER_NEIGHBOURS,
    PREPARE_THREADS,
    Options,
)
from fourd.pipeline.worker_threads import map_in_threads
from fourd.progress import progress
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.kinematic")

#: The cache entries of prepared frames.
STAGE = "kinematic-prepare"


def prepare_frames(seq: PointCloudSequence, options: Options, cache: StageCache = NO_CACHE):
    """Per-frame cleaning and normals: returns ``(points, normals)`` lists (pure per frame).

    Frames are prepared two at a time on two threads (their compiled kernels release the GIL)
    when numba's threading layer allows concurrent parallel kernels; the result is the same
    as one after the other. With a ``cache``, each prepared frame is stored as soon as it is
    done (keyed by the frame's points, normals and sensors and the two options that act on
    it), and frames found there are not prepared again."""
    frames = list(seq.frames)
    if not frames:
        return [], []
    prepared: list = [None] * len(frames)
    keys = [frame_key(frame, options) for frame in frames] if cache.enabled else None
    if keys is not None:
        for i, key in enumerate(keys):
            entry = cache.load(STAGE, key)
            if entry is not None:
                prepared[i] = (entry["points"], entry["normals"])
        found = sum(p is not None for p in prepared)
        if found:
            report_resumed(log, f"{found} of {len(frames)} frames' preparation")
    todo = [i for i, p in enumerate(prepared) if p is None]

    def keep(i, result):
        prepared[i] = result
        if keys is not None:
            cache.save(STAGE, keys[i], {"points": result[0], "normals": result[1]})

    done = map_in_threads(lambda i: _prepare_frame(frames[i], options), todo, PREPARE_THREADS)
    for i, result in zip(todo, done, strict=True):
        keep(i, result)
    return [p for p, _ in prepared], [n for _, n in prepared]


def densify_frames(
    points: list,
    normals: list,
    options: Options,
    *,
    density: float | None = None,
    first: int = 0,
    surface: tuple | None = None,
) -> tuple[list, list]:
    """The prepared frames ``points``, ``normals`` (lists of ``[P_k, 3]``), densified when
    they are sparser than the template (``options.densify``, :mod:`fourd.geometry.densify`):
    each frame's surface sampled at :data:`DENSIFIED_POINTS_PER_VERTEX` samples per template
    vertex on the first frame's surface area (a pure function of each frame, seeded by its
    index). Returned as given when the frames are dense enough or the first frame has no
    surface.

    ``density`` (samples per unit area, 0: none) decides for frames that are part of a longer
    sequence (a streamed run's later windows: :func:`densify_density` of its first), and
    ``first`` is the index of ``points[0]`` in that sequence (the seeds); ``surface``: the
    surface of ``points[0]`` when :func:`densify_density` made it."""
    if density is None:
        density, surface = densify_density(points, normals, options)
    if density <= 0:
        return points, normals
    dense_points, dense_normals = [], []
    for index in progress(range(len(points)), desc="densifying", total=len(points)):
        p, n = densify_points(points[index], normals[index], density=density,
                              surface=surface if index == 0 else None,
                              seed=options.seed + first + index)
        dense_points.append(p)
        dense_normals.append(n)
    log.info(
        "sparse frames (%d points in the median frame, %d template vertices): each frame's "
        "surface sampled, %d points in the median frame now",
        np.median([len(p) for p in points]), options.template_vertices,
        np.median([len(p) for p in dense_points]),
    )
    return dense_points, dense_normals


def densify_density(points: list, normals: list, options: Options) -> tuple[float, tuple | None]:
    """The density (samples per unit area) :func:`densify_frames` samples ``points`` at, 0
    when they are not densified, and the first frame's surface ``(vertices, faces)`` it was
    measured on (None when there is none)."""
    median = float(np.median([len(p) for p in points])) if points else 0.0
    if not options.densify or median >= options.template_vertices:
        return 0.0, None
    first = frame_surface(points[0], normals=normals[0], settings=SurfaceSettings(seed=options.seed))
    area = float(face_areas(*first).sum())
    if area <= 0:
        return 0.0, None
    return DENSIFIED_POINTS_PER_VERTEX * options.template_vertices / area, first


def frame_key(frame, options: Options) -> str:
    """The cache key of one prepared frame: its data and the options
    :func:`_prepare_frame` reads."""
    return stage_key(
        STAGE, frame.points, frame.normals, frame.sensors, options.outlier_factor,
        options.normals_k, OUTLIER_NEIGHBOURS,
    )


def _prepare_frame(frame, options: Options):
    """One frame's kept points [P', 3] and their oriented normals [P', 3]."""
    # one neighbour query per frame serves the outlier test (8 neighbours) and the normals
    # of the kept points (a margin of 4 for the dropped ones; rows that keep fewer are
    # queried again)
    distances = indices = None
    if frame.normals is None:
        k = max(OUTLIER_NEIGHBOURS, options.normals_k) + 4
        distances, indices = knn(frame.points, min(k, len(frame.points) - 1))
    elif options.outlier_factor > 0 and len(frame.points) > OUTLIER_NEIGHBOURS + 1:
        distances, _ = knn(frame.points, OUTLIER_NEIGHBOURS)
    keep = distance_ratio_inliers(
        frame.points,
        k=OUTLIER_NEIGHBOURS,
        factor=options.outlier_factor,
        statistic="mean",
        distances=distances,
    )
    p = frame.points[keep]
    if frame.normals is not None:
        return p, frame.normals[keep]
    neighbours = neighbours_among(frame.points, indices, keep, options.normals_k)
    n = estimate_normals(p, k=options.normals_k, sensors=frame.sensors, indices=neighbours).normals
    return p, n
