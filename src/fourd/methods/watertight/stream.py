"""The ``watertight`` composition over a whole capture with memory bounded by a window of frames
(issue 56): the steps of :mod:`.method`, each streamed.

1. ``kinematic`` streamed (:func:`fourd.methods.kinematic.reconstruct_streamed`) to a work file.
2. ``flow`` streamed in overlapping windows (:func:`fourd.methods.flow.reconstruct_streamed`)
   to a work file of closed meshes, one per frame.
3. The closed template (:func:`streamed_template`): the flow's surface at the first frame, as
   the signed distance to its mesh (:func:`fourd.methods.flow.mesh_distance`; the flow's solve
   is no longer in memory), bound to the kinematic first frame
   (:func:`~fourd.methods.watertight.method.closed_template`).
4. Frame by frame (:func:`closed_mesh_frames`), the template carried with the kinematic frame
   and its free vertices projected onto that frame's flow mesh, the projections smoothed over
   time [1, 2, 1] as in memory (one frame of lag), written as they come.

In memory the free vertices follow the flow's own signed distance in space-time; here they
follow the distance to each frame's flow mesh, the same surface up to its marching-cubes
facets. The default method's streamed run (:mod:`fourd.methods.auto.stream`) takes steps 3
and 4 from here. Memory holds a window of frames in steps 1-2 and one frame in step 4, plus the
output's observed flags; the work files lie in a temporary folder next to the output and go
when the run ends. With ``cache_dir`` the kinematic and flow stages resume window by window.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.cache import subfolder
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.geometry.neighbors import point_spacing
from fourd.io.npz import npz_frame_reader, npz_frames
from fourd.methods import flow, kinematic
from fourd.methods.base import run_streamed
from fourd.methods.watertight.method import (
    LOST_WARNING,
    MIN_FRAMES,
    OFF_SURFACE_CELLS,
    OFF_SURFACE_WARNING,
    ClosedTemplate,
    Options,
    WatertightDiagnostics,
    closed_frames,
    closed_template,
    flow_options,
    lost_fraction,
    off_surface_fraction,
)

log = logging.getLogger("fourd.methods.watertight")

#: Frames read from the input at once in step 4.
READ_CHUNK = 20


class StreamSummary(NamedTuple):
    """What :func:`reconstruct_streamed` did: ``frames`` written to ``output`` (an animated
    mesh of ``vertices`` vertices), the ``windows`` of the kinematic and flow stages together
    (``resumed`` of them loaded from the cache), the composition's figures
    (``diagnostics``) and the wall ``seconds``."""

    output: Path
    frames: int
    vertices: int
    windows: int
    resumed: int
    diagnostics: WatertightDiagnostics
    seconds: float


def reconstruct_streamed(
    source: FrameSource, output, options: Options | None = None
) -> StreamSummary:
    """The watertight composition of ``source``, window by window, written to ``output`` (a
    fourd ``.npz`` animated mesh, atomically: it appears when every frame is written).

    Parameters
    ----------
    source : FrameSource
        The capture, read a window at a time (:func:`fourd.io.frames.open_sequence`).
    output : path-like
        The ``.npz`` to write.
    options : Options
        ``window`` frames per window of the kinematic and flow stages (0: their streamed
        defaults, 20 for the flow), ``window_overlap`` frames shared by consecutive flow
        windows; ``cache_dir`` keeps their finished windows; the other options are the flow's.

    Raises
    ------
    InputError
        Too few frames, an output that is not ``.npz``, a bad frame.

    References
    ----------
    000_00387fefe94cc850.txt and 002_382acf333feb7a6e.txt as :mod:`fourd.methods.watertight`;
    the windows are this project's (issue 56).
    """
    options = options or Options()
    return run_streamed(
        "watertight", source, output, MIN_FRAMES, lambda output, work: _run(source, output, options, work)
    )


def streamed_flow_options(options: flow.Options, window: int) -> flow.Options:
    """``options`` for the flow stage of a streamed composition: windows of ``window`` frames
    (0: :data:`fourd.methods.flow.STREAM_WINDOW`), the overlap at most half of it."""
    window = window or flow.STREAM_WINDOW
    return dataclasses.replace(
        options, window=window, window_overlap=min(options.window_overlap, window // 2)
    )


def _run(source: FrameSource, output: Path, options: Options, work: Path) -> StreamSummary:
    opened, meshes = work / "kinematic.npz", work / "flow.npz"
    opened_summary = kinematic.reconstruct_streamed(
        source, opened,
        kinematic.Options(window=options.window, cache_dir=subfolder(options.cache_dir, "kinematic")),
    )
    flowing = dataclasses.replace(
        streamed_flow_options(flow_options(options), options.window),
        cache_dir=subfolder(options.cache_dir, "flow"),
    )
    flowed = flow.reconstruct_streamed(source, meshes, flowing)
    spacing = flowed.spacing / flowing.refine
    template, lost = streamed_template(
        first_points(source), opened, meshes, float(source.times[0]), flowed.spacing, spacing
    )
    if lost > LOST_WARNING:
        log.warning(
            "watertight: the flow's surface lacks %.1f%% of the tracked first frame (a thin "
            "or fast part it lags), and so does the closed result; the kinematic method keeps "
            "it", 100 * lost,
        )
    off_surface: list[float] = []
    started = _time.perf_counter()
    with (
        npz_frame_reader(opened) as reader,
        np.load(meshes, allow_pickle=False) as data,
        npz_frames(output, faces=template.faces, times=source.times, rest=template.rest) as out,
    ):
        for vertices, observed, _ in closed_mesh_frames(
            template, reader, flow_meshes(data, len(source)), input_frames(source),
            source.times, spacing, off_surface,
        ):
            out.write(vertices, observed)
            if out.written % READ_CHUNK == 0 or out.written == len(source):
                log.info("watertight: %d of %d frames written (%.1f s)", out.written,
                         len(source), _time.perf_counter() - started)
    warn_off_surface(off_surface, log, "watertight")
    diagnostics = WatertightDiagnostics(flowed.mass_error, float(max(off_surface)), lost)
    return StreamSummary(
        output, len(source), len(template.rest), opened_summary.windows + flowed.windows,
        opened_summary.resumed + flowed.resumed, diagnostics, 0.0,
    )


def first_points(source: FrameSource) -> np.ndarray:
    """The points [P, 3] of the first frame of ``source`` with at least four."""
    for k in range(len(source)):
        points = source.read(k, k + 1).frames[0].points
        if len(points) >= 4:
            return points
    raise InputError("no frame has points")


def input_frames(source: FrameSource) -> Iterator:
    """The frames of ``source`` in order, read :data:`READ_CHUNK` at a time."""
    for start in range(0, len(source), READ_CHUNK):
        yield from source.read(start, start + READ_CHUNK).frames


def flow_meshes(data, count: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The first ``count`` (vertices, faces) of an open MeshSequence ``.npz``, one at a time."""
    for t in range(count):
        yield data[f"vertices_{t}"], data[f"faces_{t}"]


def streamed_template(
    first: np.ndarray, opened: Path, meshes: Path, time: float, flow_spacing: float,
    spacing: float,
) -> tuple[ClosedTemplate, float]:
    """Step 3: the closed template and the fraction of the kinematic first frame it lacks
    (:class:`~fourd.methods.watertight.method.Closing`'s ``lost``). ``first`` [P, 3] is the
    first frame's points (the template's cell, as the kinematic method sizes its own),
    ``opened`` the kinematic result's ``.npz``, ``meshes`` the flow's, ``flow_spacing`` its grid
    spacing (the binding's reach is half of it) and ``spacing`` the signed distance's (input
    units)."""
    cell = kinematic.template_cell_size(
        first, point_spacing(first), kinematic.Options().template_vertices
    )
    with np.load(meshes, allow_pickle=False) as data:
        mesh = next(flow_meshes(data, 1))
    field = flow.mesh_distance(*mesh, time, spacing)
    with npz_frame_reader(opened) as reader:
        start = next(reader.frames())
        faces = reader.faces
    template = closed_template(
        start, faces, field, time, bounds=field.bounds(), cell_size=cell, reach=0.5 * flow_spacing,
    )
    return template, lost_fraction(template.rest, start, faces)


def closed_mesh_frames(
    template: ClosedTemplate,
    opened,
    meshes: Iterator,
    frames: Iterator,
    times: np.ndarray,
    spacing: float,
    off_surface: list,
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Step 4: the closed template at every frame, in order, as (vertices [N, 3], observed
    [N], the frame's points [P, 3]) (:func:`~fourd.methods.watertight.method.closed_frames`);
    the off-surface fraction of every frame
    (:func:`~fourd.methods.watertight.method.off_surface_fraction`) appended to
    ``off_surface``.

    ``opened`` is the kinematic result's reader, ``meshes`` the flow's (vertices, faces) per
    frame, ``frames`` the input frames, ``spacing`` the signed distances' grid spacing."""
    def inputs():
        for k, (vertices, seen, mesh, frame) in enumerate(
            zip(opened.frames(), opened.observed, meshes, frames, strict=True)
        ):
            at = float(times[k])
            field = flow.mesh_distance(*mesh, at, spacing) if len(mesh[1]) else None
            yield vertices, seen, field, at, (field, at, frame.points)

    for vertices, observed, (field, at, points) in closed_frames(template, inputs(), len(times)):
        off_surface.append(
            0.0 if field is None else off_surface_fraction(
                vertices, field, at, OFF_SURFACE_CELLS * spacing, points
            )
        )
        yield vertices, observed, points


def warn_off_surface(off_surface: list, logger: logging.Logger, method: str) -> None:
    """Warn on ``logger`` when in some frame more than :data:`OFF_SURFACE_WARNING` of the
    closed mesh lies far from both the flow's surface and the frame's points (``off_surface``,
    per frame); ``method`` names the method in the message."""
    if max(off_surface, default=0.0) > OFF_SURFACE_WARNING:
        logger.warning(
            "%s: in some frames more than %.1f%% of the closed mesh lies far from both the "
            "flow's surface and the frame's points (at most %.1f%%, frame %d): the tracking "
            "lost part of it", method, 100 * OFF_SURFACE_WARNING, 100 * max(off_surface),
            int(np.argmax(off_surface)),
        )

