"""The default method over a whole capture with memory bounded by a window of frames (issue
56): the rule of :mod:`fourd.methods.auto.method`, each of its stages streamed.

1. ``kinematic`` streamed (:func:`fourd.methods.kinematic.reconstruct_streamed`) to a work
   file; an open surface (the vector area of its urshape) ends in step 5 with it.
2. ``flow`` streamed (:func:`fourd.methods.flow.reconstruct_streamed`) to a work file of
   closed meshes; where their number of parts changes over the capture (a split or a merge),
   that file is the result.
3. The closed template: the flow's surface at the first frame, as a signed distance to its
   mesh (:func:`fourd.methods.flow.mesh_distance`: the flow's solve is no longer in memory),
   bound to the kinematic first frame (:func:`fourd.methods.watertight.stream.streamed_template`,
   the streamed ``watertight``'s step); when the flow lacks more than ``lost_limit`` of it,
   the kinematic result goes to step 5.
4. Frame by frame, the template carried with the kinematic frame and its free vertices
   projected onto that frame's flow surface, the projections smoothed over time [1, 2, 1] as
   in memory, one frame of lag (:func:`fourd.methods.watertight.stream.closed_mesh_frames`).
5. The fit to the frames along the normals (:func:`fourd.geometry.surface_fit.fit_along_normals`)
   over chunks of :data:`FIT_CHUNK` frames with :data:`FIT_MARGIN` frames on both sides: its
   two passes of a [1, 2, 1] filter over time reach two frames, so every written frame is
   the one a fit of the whole capture gives.

Memory holds a window of frames in steps 1-2 and a chunk in steps 4-5, plus the output's
observed flags; the work files lie in a temporary folder next to the output and go when the
run ends. With ``cache_dir`` the kinematic and flow stages resume window by window; steps 3-5
run again (a fraction of the time).
"""

from __future__ import annotations

import functools
import logging
import os
import time as _time
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fourd.animation import MeshSequence
from fourd.cache import subfolder
from fourd.frame_source import FrameSource
from fourd.geometry.surface_fit import fit_along_normals
from fourd.io.npz import npz_frame_reader, npz_frames
from fourd.methods import flow, kinematic
from fourd.methods.auto.method import (
    MIN_FRAMES,
    AutoDiagnostics,
    Options,
    fit_points,
    fit_scales,
    part_counts,
    splits,
    vector_area_fraction,
)
from fourd.methods.base import run_streamed
from fourd.methods.watertight.stream import (
    closed_mesh_frames,
    first_points,
    flow_meshes,
    input_frames,
    streamed_flow_options,
    streamed_template,
    warn_off_surface,
)

log = logging.getLogger("fourd.methods.auto")

#: Frames fitted at once in step 5 (and read at once in steps 4-5).
FIT_CHUNK = 20
#: Frames fitted on both sides of a chunk and not written from it: the fit's reach in time.
FIT_MARGIN = 2


class StreamSummary(NamedTuple):
    """What :func:`reconstruct_streamed` did: ``frames`` written to ``output`` (an animated
    mesh of ``vertices`` vertices, or the flow's meshes where the shape splits, then 0), the
    ``windows`` of the kinematic and flow stages together (``resumed`` of them loaded from
    the cache), the decision's figures (``diagnostics``) and the wall ``seconds``."""

    output: Path
    frames: int
    vertices: int
    windows: int
    resumed: int
    diagnostics: AutoDiagnostics
    seconds: float


def reconstruct_streamed(
    source: FrameSource, output, options: Options | None = None
) -> StreamSummary:
    """The default method's result for ``source``, window by window, written to ``output`` (a
    fourd ``.npz``, atomically: it appears when every frame is written).

    Parameters
    ----------
    source : FrameSource
        The capture, read a window at a time (:func:`fourd.io.frames.open_sequence`).
    output : path-like
        The ``.npz`` to write: an animated mesh, or the flow's closed meshes (a
        MeshSequence) where the shape splits or merges.
    options : Options
        ``window`` frames per window of the kinematic and flow stages (0: their streamed
        defaults, 20); ``cache_dir`` keeps their finished windows.

    Raises
    ------
    InputError
        Too few frames, an output that is not ``.npz``, a bad frame.

    References
    ----------
    000_00387fefe94cc850.txt and 002_382acf333feb7a6e.txt as :mod:`fourd.methods.auto`;
    the windows are this project's (issue 56).
    """
    options = options or Options()
    return run_streamed(
        "auto", source, output, MIN_FRAMES, lambda output, work: _Run(source, output, options, work).run()
    )


class _Run:
    """One streamed run: the stages of the module docstring over ``source``."""

    def __init__(self, source: FrameSource, output: Path, options: Options, work: Path):
        self.source, self.output, self.options, self.work = source, output, options, work
        self.windows = self.resumed = 0
        self.flow_options = streamed_flow_options(
            flow.Options(resolution=options.resolution, cache_dir=subfolder(options.cache_dir, "flow")),
            options.window,
        )

    def run(self) -> StreamSummary:
        options = self.options
        opened = self._kinematic()
        with npz_frame_reader(opened) as reader:
            openness = vector_area_fraction(reader.rest, reader.faces)
        if options.surface == "open" or (
            options.surface == "auto" and openness > options.open_area
        ):
            log.info(
                "auto: an open surface (the first frame's vector area is %.2f of its area, "
                "over %.2f): the kinematic result", openness, options.open_area,
            )
            return self._open(opened, AutoDiagnostics(1.0, openness, 0.0))
        meshes, flowed = self._flow()
        with np.load(meshes, allow_pickle=False) as data:
            parts = np.concatenate([
                part_counts(MeshSequence((mesh,)), options.split_part)
                for mesh in flow_meshes(data, len(self.source))
            ])
        if splits(parts):
            log.warning(
                "auto: the shape splits or merges (parts per frame %s): one connectivity cannot "
                "follow it, so the result is the flow's closed meshes, one per frame, without "
                "correspondences", " ".join(map(str, parts)),
            )
            os.replace(meshes, self.output)
            return self._summary(0, AutoDiagnostics(0.0, openness, 1.0, flowed.mass_error))
        template, lost = streamed_template(
            self._first_points, opened, meshes, float(self.source.times[0]), flowed.spacing,
            flowed.spacing / self.flow_options.refine,
        )
        if lost > options.lost_limit:
            log.warning(
                "auto: the flow's surface lacks %.1f%% of the tracked first frame (over %.1f%%; "
                "a thin, fast part it lags), so the result is the kinematic one, open where no "
                "frame saw (method watertight closes it anyway)", 100 * lost,
                100 * options.lost_limit,
            )
            return self._open(
                opened, AutoDiagnostics(1.0, openness, 0.0, flowed.mass_error, None, lost)
            )
        log.info(
            "auto: a closed object (vector area %.2f of the area): the kinematic result closed "
            "by the flow's surfaces", openness,
        )
        off_surface = []
        with npz_frame_reader(opened) as reader, np.load(meshes, allow_pickle=False) as data:
            closed = closed_mesh_frames(
                template, reader, flow_meshes(data, len(self.source)), input_frames(self.source),
                self.source.times, flowed.spacing / self.flow_options.refine, off_surface,
            )
            self._write(closed, template.faces, template.rest)
        warn_off_surface(off_surface, log, "auto")
        diagnostics = AutoDiagnostics(
            0.0, openness, 0.0, flowed.mass_error, float(max(off_surface)), lost
        )
        return self._summary(len(template.rest), diagnostics)

    def _kinematic(self) -> Path:
        path = self.work / "kinematic.npz"
        summary = kinematic.reconstruct_streamed(
            self.source, path,
            kinematic.Options(
                seed=self.options.seed, window=self.options.window,
                cache_dir=subfolder(self.options.cache_dir, "kinematic"),
            ),
        )
        self.windows += summary.windows
        self.resumed += summary.resumed
        return path

    def _flow(self):
        path = self.work / "flow.npz"
        summary = flow.reconstruct_streamed(self.source, path, self.flow_options)
        self.windows += summary.windows
        self.resumed += summary.resumed
        return path, summary

    def _open(self, opened: Path, diagnostics: AutoDiagnostics) -> StreamSummary:
        """Step 5 on the kinematic result."""
        with npz_frame_reader(opened) as reader:
            frames = (
                (vertices, seen, frame.points)
                for vertices, seen, frame in zip(
                    reader.frames(), reader.observed, input_frames(self.source), strict=True
                )
            )
            self._write(frames, reader.faces, reader.rest)
            return self._summary(reader.vertex_count, diagnostics)

    def _write(self, frames: Iterator, faces: np.ndarray, rest: np.ndarray) -> None:
        """Step 5 on ``frames`` ((vertices [N, 3], observed [N], points [P, 3]) in order), to
        the output."""
        started = _time.perf_counter()
        with npz_frames(self.output, faces=faces, times=self.source.times, rest=rest) as out:
            for vertices, observed in _fitted(
                frames, faces, len(self.source), self.options, self._scales()
            ):
                out.write(vertices, observed)
                log.info(
                    "auto: frames %d-%d of %d written (%.1f s)", out.written - len(vertices),
                    out.written - 1, len(self.source), _time.perf_counter() - started,
                )

    @functools.cached_property
    def _first_points(self) -> np.ndarray:
        return first_points(self.source)

    def _scales(self) -> tuple[float, float] | None:
        if not self.options.fit_frames:
            return None
        return fit_scales(fit_points([self._first_points])[0], self.options)

    def _summary(self, vertices: int, diagnostics: AutoDiagnostics) -> StreamSummary:
        return StreamSummary(
            self.output, len(self.source), vertices, self.windows, self.resumed, diagnostics, 0.0
        )


def _fitted(frames: Iterator, faces: np.ndarray, count: int, options: Options,
            scales: tuple[float, float] | None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Step 5: ``frames`` ((vertices [N, 3], observed [N], points [P, 3]), ``count`` of them
    in order) fitted along their normals onto their points with ``scales`` (radius, reach;
    None: not fitted), as (vertices [k, N, 3], observed [k, N]) chunks in order."""
    buffer, first, written = [], 0, 0  # frames first.. held, frames before written are out
    for vertices, observed, points in frames:
        buffer.append((vertices, observed, points))
        end = first + len(buffer)
        if end < count and end - written < FIT_CHUNK + FIT_MARGIN:
            continue
        last = end if end == count else end - FIT_MARGIN
        vertices = np.stack([v for v, _, _ in buffer])
        if scales is not None:
            vertices = fit_along_normals(
                vertices, faces, fit_points([p for _, _, p in buffer]),
                radius=scales[0], reach=scales[1],
            ).vertices
        yield vertices[written - first : last - first], np.stack(
            [o for _, o, _ in buffer[written - first : last - first]]
        )
        written = last
        drop = max(0, written - FIT_MARGIN - first)
        buffer, first = buffer[drop:], first + drop
