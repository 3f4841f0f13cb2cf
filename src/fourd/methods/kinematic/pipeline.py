"""The ``kinematic`` pipeline: prepared frames, the 4D fit, then :func:`.animate`
(urshape and sliding); see the package docstring for the paper and what is beyond it.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.appearance.color_guide import guide_colors
from fourd.cache import StageCache
from fourd.errors import InputError
from fourd.geometry.fans import split_pinches
from fourd.geometry.neighbors import point_spacing
from fourd.methods.kinematic.animate import animate
from fourd.methods.kinematic.field import fit_key, fit_windows, space_time_points
from fourd.methods.kinematic.frames import densify_frames, prepare_frames
from fourd.methods.kinematic.mpu4d import MPUOptions
from fourd.methods.kinematic.options import MIN_FRAMES, Options
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.kinematic")

#: The video's anchors are tracked from one point per cube of this many point spacings
#: (``AnchorOptions.sources``): the sliding blends them over two template edges anyway.
ANCHOR_SOURCES = 2.0


def reconstruct(
    seq: PointCloudSequence, options: Options | None = None, *, edge_stiffness: tuple | None = None,
    split_pinched: bool = True,
) -> AnimatedMesh:
    """Animated mesh from a point-cloud sequence by 4D MPU + urshape + ARAP sliding.

    Returns an :class:`AnimatedMesh` with ``rest`` the urshape; one frame per output time
    (default: per input frame). Raises :class:`InputError` when the sequence is too short or
    the implicit has no surface at the first time.

    With ``options.cache_dir``, the prepared frames, the 4D fit (each window), the urshape
    and every slid frame are kept there as they finish, and a rerun resumes after the last
    one (:mod:`fourd.cache`).

    ``edge_stiffness`` (edges as pairs of vertex ids, and their weights) is passed to the
    sliding (:attr:`~fourd.methods.kinematic.sliding.SlideOptions.edge_stiffness`); its ids
    are those of a result made with ``split_pinched`` False, which leaves the urshape's pinched
    vertices as they are (else each gets a copy per fan of faces, :func:`without_pinches`).

    References
    ----------
    Süßmuth, Winter, Greiner: Reconstructing animated meshes from time-varying point clouds,
    SGP 2008 (000_00387fefe94cc850.txt).
    """
    options = options or Options()
    if len(seq) < MIN_FRAMES:
        raise InputError(f"kinematic needs at least {MIN_FRAMES} frames, got {len(seq)}")
    started = _time.perf_counter()
    cache = StageCache(options.cache_dir)
    times = seq.times
    points, normals = densify_frames(*prepare_frames(seq, options, cache), options)
    spacing = point_spacing(points[0], seed=options.seed)
    steps = np.diff(times)
    time_unit = float(np.median(steps))
    delta = spacing * options.time_scale
    time_scale = delta / time_unit
    stride = options.fit_stride
    stp = space_time_points(
        [p[::stride] for p in points],
        [n[::stride] for n in normals],
        times,
        delta=delta,
        time_origin=times[0],
        time_unit=time_unit,
    )
    fit = dict(
        mpu_options=fit_options(options, spacing),
        window=options.window,
        overlap=options.window_overlap,
        time_origin=times[0],
        time_scale=time_scale,
    )
    key = fit_key(stp, times, **fit) if cache.enabled else ""
    field = fit_windows(stp, times, **fit, cache=cache, key=key)
    fitted = _time.perf_counter()
    log.info("4D fit: %.2f s", fitted - started)

    anchors = None
    if options.video_anchors and getattr(seq, "video", None) is not None:
        anchors = video_anchors(points, times, seq.video, options, seq.names)
    colors = None
    if options.color_guide:
        colors = guide_colors(seq, points, normals)
    result = animate(
        field, points, normals, times, spacing=spacing, options=options, cache=cache,
        field_key=key, edge_stiffness=edge_stiffness, anchors=anchors, colors=colors,
    )
    if split_pinched:
        result = without_pinches(result)
    finished = _time.perf_counter()
    log.info(
        "kinematic: %d frames in %.2f s (fit %.2f, urshape and sliding %.2f)",
        len(result.times),
        finished - started,
        fitted - started,
        finished - fitted,
    )
    return result


def without_pinches(result: AnimatedMesh) -> AnimatedMesh:
    """``result`` with one copy of each pinched vertex per fan of faces
    (:func:`~fourd.geometry.fans.split_pinches`): the urshape's marching cubes, kept only in
    cells near the data, leaves vertices where two fans of faces meet at a point, which the
    tools a result goes to reject. The copies move with their vertex in every frame, so the
    surface and its motion are the sliding's, to the bit."""
    faces, source = split_pinches(result.faces, result.vertex_count)
    if len(source) == result.vertex_count:
        return result
    return dataclasses.replace(
        result, faces=faces, vertices=result.vertices[:, source], observed=result.observed[:, source],
        rest=None if result.rest is None else result.rest[source],
        colors=None if result.colors is None else result.colors[:, source],
    )


def video_anchors(points, times, video, options: Options, names=()):
    """The anchor tracks between consecutive frames (:func:`fourd.appearance.anchors`) of
    the frames ``points`` (list of [P_k, 3], as prepared: the anchors' own outlier removal
    would repeat the cleaning) at ``times``, filmed by ``video`` (one image per camera and
    frame)."""
    from fourd.appearance.anchor_tracks import cleaned_anchors

    anchors = cleaned_anchors(
        points, times, video, names, texture=options.anchor_texture, sources=ANCHOR_SOURCES
    )
    log.info("anchors from the video: %d over %d frame pairs", anchors.total, len(anchors))
    return anchors


def fit_options(options: Options, spacing: float) -> MPUOptions:
    """The 4D fit's options for frames whose point spacing is ``spacing``."""
    return MPUOptions(
        error=options.mpu_error or 2.0 * spacing,
        min_points=options.min_points,
        error_quantile=options.error_quantile,
    )
