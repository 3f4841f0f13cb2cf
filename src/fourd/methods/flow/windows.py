"""``flow`` over a sequence longer than one solve: overlapping windows of frames whose surfaces
are blended over the frames they share (issue 56), in memory (:func:`reconstruct_windowed`,
``Options.window``) or streamed from a :class:`~fourd.frame_source.FrameSource` to a ``.npz``
(:func:`reconstruct_streamed`, ``fourd reconstruct --method flow --stream``).

Each window is an ordinary flow solve (:func:`~.pipeline.run`) of its frames alone, on a grid
fitted to them, so memory is bounded by the window and not by the sequence. A frame that two
windows share gets from each the signed distance to that window's mesh
(:func:`~.post.redistanced`); their blend ``(1 - w) d_A + w d_B``, ``w = k / (m + 1)`` at the
``k``-th of ``m`` shared frames, is sampled on the later window's grid and meshed like a solve's
frame (marching cubes, small parts and cavities dropped). The surface so passes from the earlier
solve to the later one a step per frame, and each window's first and last frames, where its
solve has data on one side in time only, weigh least. Each window's mass is its own solve's;
over the shared frames it is blended the same way. With ``mass_levels`` the meshes of every
window enclose one volume, the mean contoured volume of all windows solved so far (the flow
conserves mass over the whole sequence, not only within one solve; one solve's meshes enclose
the mean of its frames', :func:`~.mass_levels.mass_meshes`).

No frame is in more than two windows: consecutive windows start ``window - window_overlap``
frames apart, and the last one ends at the last frame, starting no earlier than where the one
before its neighbour ends (:func:`window_ranges`).

References
----------
002_382acf333feb7a6e.txt (the solve of every window); the windows are this project's (issue 56:
"flow volumes overlap in time and blend").
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.animation import MeshSequence
from fourd.cache import StageCache, option_values, pack_list, report_resumed, stage_key, unpack_list
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.geometry.meshes import face_volumes
from fourd.io.npz import npz_meshes, streamed_output
from fourd.methods.flow.options import MIN_FRAMES, Options
from fourd.methods.flow.pipeline import (
    check_missing_frames,
    level_meshes,
    mass_conservation_error,
    run,
)
from fourd.methods.flow.post import FlowField, drop_cavities, extract_mesh, redistanced

log = logging.getLogger("fourd.methods.flow")

#: Frames per window of a streamed run when ``options.window`` is 0 (the paper solved about
#: 20 frames at a time).
STREAM_WINDOW = 20
#: The cache entries of finished windows.
STAGE = "flow-window"


def window_ranges(count: int, window: int, overlap: int) -> list[tuple[int, int]]:
    """The windows ``(first, last)`` (inclusive) over ``count`` frames: ``window`` frames each
    (the last may be shorter, never shorter than ``window - overlap + 1`` frames), consecutive
    ones sharing at least ``overlap`` (at most ``window / 2``) frames and no frame in more than
    two.

    >>> window_ranges(37, 20, 4)
    [(0, 19), (16, 35), (20, 36)]
    >>> window_ranges(12, 20, 4)
    [(0, 11)]
    """
    if count <= window:
        return [(0, count - 1)]
    starts = list(range(0, count - window, window - overlap))
    # the last window ends at the last frame and starts after the one before its neighbour ends
    starts.append(max(count - window, starts[-1] + overlap))
    return [(a, min(a + window, count) - 1) for a in starts]


class WindowedFlow(NamedTuple):
    """What :func:`solve_windows` did: the ``windows`` (``resumed`` of them loaded from the
    cache), every frame's ``mass`` (input units^3, as :class:`~.pipeline.FlowResult`'s), the
    median of the windows' grid ``spacing`` (input units) and the wall ``seconds``."""

    windows: list
    resumed: int
    mass: np.ndarray
    spacing: float
    seconds: float


def solve_windows(
    source: FrameSource, options: Options, write: Callable[[np.ndarray, np.ndarray], None]
) -> WindowedFlow:
    """Solve ``source`` window by window and give every frame's closed mesh, in order, to
    ``write(vertices [N, 3], faces [F, 3])`` as soon as it is final.

    ``options.window`` frames per window (0: :data:`STREAM_WINDOW`); with ``options.cache_dir``
    each finished window is kept (its meshes and what the next window blends with), keyed by
    the frames read so far and the options, and a rerun resumes after the last one.
    """
    started = _time.perf_counter()
    window = options.window or STREAM_WINDOW
    ranges = window_ranges(len(source), window, min(options.window_overlap, window // 2))
    check_missing_frames(options.missing_frames, len(source))
    cache = StageCache(options.cache_dir)
    key = stage_key(STAGE, option_values(options), source.times) if cache.enabled else ""
    mass = np.zeros(len(source))
    shared = None  # the previous window's signed distances over the frames it shares
    volumes = np.zeros(2)  # sum and count of the windows' contoured volumes
    spacings = []
    resumed = 0
    for index, (first, last) in enumerate(ranges):
        seq = source.read(first, last + 1)
        if cache.enabled:
            key = stage_key(key, index, [(f.points, f.sensors) for f in seq.frames])
        entry = cache.load(STAGE, key) if cache.enabled else None
        if entry is None:
            if resumed and resumed == index:
                report_resumed(log, f"{resumed} of {len(ranges)} windows")
            following = ranges[index + 1][0] if index + 1 < len(ranges) else last + 1
            entry = _window(seq, first, following, shared, volumes, options)
            if cache.enabled:
                cache.save(STAGE, key, entry)
        else:
            resumed += 1
        del seq
        meshes = list(zip(unpack_list(entry, "vertices"), unpack_list(entry, "faces"), strict=True))
        done = int(entry["first_written"])
        mass[done : done + len(meshes)] = entry["mass"]
        spacings.append(float(entry["grid_spacing"]))
        for vertices, faces in meshes:
            write(vertices, faces)
        shared, volumes = _Shared.of(entry), entry["volumes"]
        log.info(
            "flow window %d of %d (frames %d-%d): %.1f s so far",
            index + 1, len(ranges), first, last, _time.perf_counter() - started,
        )
    if resumed == len(ranges):
        report_resumed(log, f"all {resumed} windows")
    return WindowedFlow(
        ranges, resumed, mass, float(np.median(spacings)), _time.perf_counter() - started
    )


class _Shared(NamedTuple):
    """A window's signed distances [m, X, Y, Z] on its fine grid over the ``m`` frames it
    shares with the next window, and their masses."""

    distances: FlowField
    mass: np.ndarray

    @classmethod
    def of(cls, entry) -> _Shared | None:
        if len(entry["shared_mass"]) == 0:
            return None
        field = FlowField(
            entry["shared_values"], entry["shared_origin"], float(entry["shared_spacing"]),
            entry["shared_times"],
        )
        return cls(field, entry["shared_mass"])


def _window(seq, first: int, following: int, shared: _Shared | None, volumes: np.ndarray,
            options: Options) -> dict:
    """Solve one window (its frames ``seq``, the first being frame ``first``; the next window
    starts at frame ``following``): the meshes it makes final, blended with ``shared`` over
    the frames the previous window shares, and its signed distances over those it shares with
    the next. ``volumes`` [2], the sum and count of the contoured volumes of the windows
    before; with ``mass_levels`` every mesh is moved to enclose the mean over those and this
    window's (the flow conserves mass over the whole sequence, not only within a solve)."""
    local = dataclasses.replace(
        options,
        window=0,
        cache_dir=None,
        mass_levels=False,
        missing_frames=tuple(i - first for i in options.missing_frames
                             if first <= i < first + len(seq)),
    )
    result = run(seq, local)
    meshes = list(result.meshes.meshes)
    contoured = np.array([face_volumes(v, f).sum() for v, f in meshes])
    contoured = contoured[contoured > 0]
    volumes = volumes + [contoured.sum(), len(contoured)]
    if options.mass_levels and volumes[1]:
        meshes = level_meshes(
            meshes, result.frame_points, result.mass, result.grid.h, options,
            volume=volumes[0] / volumes[1],
        )
    blended = 0 if shared is None else len(shared.mass)
    own = following - first  # frames up to the next window's first
    mass = result.mass.copy()
    # the signed distances over the frames shared with the windows before and after
    needed = [*range(blended), *range(own, len(seq))]
    distances = redistanced(
        result.field, result.grid.frame_slice[needed], [meshes[i] for i in needed]
    )
    for k in range(blended):
        w = (k + 1) / (blended + 1)
        meshes[k] = _blend(shared.distances, k, distances, k, w, options.min_component)
        mass[k] = (1 - w) * shared.mass[k] + w * mass[k]
    later = slice(blended, None)
    return {
        "first_written": np.array(first),
        "mass": mass[:own],
        **pack_list("vertices", [v for v, _ in meshes[:own]]),
        **pack_list("faces", [f for _, f in meshes[:own]]),
        "volumes": volumes,
        "grid_spacing": np.array(result.grid.h),
        "shared_mass": mass[own:],
        "shared_values": distances.values[later],
        "shared_origin": distances.origin,
        "shared_spacing": np.array(distances.spacing),
        "shared_times": distances.times[later],
    }


def _blend(earlier: FlowField, i: int, later: FlowField, j: int, weight: float,
           min_component: float) -> tuple[np.ndarray, np.ndarray]:
    """The closed mesh of ``(1 - weight)`` times ``earlier``'s slice ``i`` plus ``weight``
    times ``later``'s slice ``j``, both signed distances, on ``later``'s grid."""
    shape = later.values.shape[1:]
    theirs = earlier.value(later.nodes(), earlier.times[i]).reshape(shape)
    values = (1 - weight) * theirs + weight * later.values[j]
    one = FlowField(values[None], later.origin, later.spacing, later.times[j : j + 1])
    vertices, faces, _ = drop_cavities(*extract_mesh(one, 0, min_component=min_component))
    return vertices, faces


class WindowedResult(NamedTuple):
    """:func:`reconstruct_windowed`'s meshes and figures."""

    meshes: MeshSequence
    mass: np.ndarray
    mass_error: float
    windows: list
    seconds: float


def reconstruct_windowed(seq, options: Options) -> WindowedResult:
    """The closed meshes of a sequence in memory (``PointCloudSequence``), solved in windows
    of ``options.window`` frames (:func:`solve_windows`)."""
    meshes = []
    solved = solve_windows(FrameSource.of(seq), options, lambda v, f: meshes.append((v, f)))
    return WindowedResult(
        MeshSequence(tuple(meshes), seq.times), solved.mass,
        mass_conservation_error(solved.mass), solved.windows, solved.seconds,
    )


class StreamSummary(NamedTuple):
    """What :func:`reconstruct_streamed` did: ``frames`` written to ``output``, the number of
    ``windows`` (``resumed`` of them loaded from the cache), the mass conservation error over
    the whole sequence, the median of the windows' grid ``spacing`` (input units) and the
    wall ``seconds``."""

    output: Path
    frames: int
    windows: int
    resumed: int
    mass_error: float
    spacing: float
    seconds: float


def reconstruct_streamed(source: FrameSource, output, options: Options | None = None) -> StreamSummary:
    """Closed meshes of ``source`` by ``flow``, window by window, written to ``output`` (a
    fourd ``.npz`` of per-frame meshes, atomically: it appears when every frame is written).

    Parameters
    ----------
    source : FrameSource
        The capture, read a window at a time (:func:`fourd.io.frames.open_sequence`).
    output : path-like
        The ``.npz`` to write (:mod:`fourd.io.npz`'s MeshSequence layout).
    options : Options
        ``window`` frames per window (0: :data:`STREAM_WINDOW`), ``window_overlap`` shared;
        ``cache_dir`` keeps every finished window.

    Raises
    ------
    InputError
        Too few frames, an output that is not ``.npz``, a bad frame.
    """
    options = options or Options()
    output = streamed_output(output)
    if len(source) < MIN_FRAMES:
        raise InputError(f"flow needs at least {MIN_FRAMES} frames, got {len(source)}")
    with npz_meshes(output, times=source.times) as out:
        solved = solve_windows(source, options, out.write)
    error = mass_conservation_error(solved.mass)
    log.info("flow, streamed: %d frames in %.1f s, mass conservation error %.2f%%",
             len(source), solved.seconds, 100 * error)
    return StreamSummary(output, len(source), len(solved.windows), solved.resumed, error,
                         solved.spacing, solved.seconds)

