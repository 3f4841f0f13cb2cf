"""``assembly`` over a whole capture with memory bounded by a window of frames (issue 56):
frames read window by window from a :class:`~fourd.frame_source.FrameSource`, each window
assembled by its own hierarchy and merged onto the frames before it, and the animated mesh
written frame by frame.

With ``paste`` and ``correct`` off a merge never changes its left block's frames: the merged
block is the left block's frames followed by the right block's, carried into the left
block's connectivity by the pair map of the left block's last frame. So once a window is
merged onto the frames before it, its frames are final, and the next window's merge needs
only its last frame. Each window's merges are
:func:`~fourd.methods.assembly.hierarchy.assemble`'s with ``onto`` (that last frame as block
0, the window's frames as the others): the maps of the window's pairs and the seam's pair run
side by side in the merge processes. Then the window's frames are fitted, each from the one
before: the rest fit (:class:`~fourd.methods.assembly.rest_fit.RestFit`, against the first
frame's shape) and the colour fit (:class:`~fourd.methods.assembly.color_fit.ColorFit`,
against its colours); the holes found in the first frame are closed in every frame
(:class:`~fourd.geometry.hole_closing.HoleClosing`).

The seam's map starts from the previous window's last frame **as fitted**, not as assembled,
and the fits' corrections start again from nothing: a chain of pair maps slides and wears
the mesh from map to map, and without this the next window's maps would start from the
worn mesh, so over a long take the wear grew until a seam's map failed (a sparse take of
1,000 frames: correspondence 0.058 mean, 0.16 last, climbing 0.01 per 100 frames; re-anchored
at every seam 0.028 / 0.041, 0.0015 per 100 frames; ``benchmarks/METHODS.md``). The
windows in memory (``reconstruct`` with ``window``, :func:`assemble_in_windows`) are this
same loop. What the run over a whole sequence decides from all frames is decided per window:
where the colours come from (the points' when every frame of the window has them, else the
video), and which frame an empty frame borrows its mesh from. With video anchors each window
tracks its pairs from two frames before its first (the tracking of a pair reuses the images
as the pair before left them), the seam's pair included.

Memory holds a window of frames, their meshes and the window's block, plus the output's
observed flags; the positions go to the output as they are final. With ``options.cache_dir``
each frame's mesh and each map are kept (as in memory), and each finished window (its frames
as written and what the next window starts from), keyed by the frames read so far and the
options: a rerun resumes after the last finished window.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time
from contextlib import ExitStack

import numpy as np

from fourd.cache import StageCache, option_values, report_resumed, stage_key
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.geometry.hole_closing import HoleClosing, holes_to_close
from fourd.io.npz import npz_frames, streamed_output
from fourd.methods.assembly.color_fit import ColorFit, frame_colors
from fourd.methods.assembly.hierarchy import Block, MergeReport, assemble, merge_pool
from fourd.methods.assembly.method import (
    MIN_FRAMES,
    base_blocks,
    frame_meshes,
    frame_pair_guides,
    takes_video_anchors,
)
from fourd.methods.assembly.options import ANCHOR_SOURCES, STREAM_WINDOW, Options
from fourd.methods.assembly.rest_fit import RestFit
from fourd.methods.base import StreamSummary
from fourd.progress import progress

log = logging.getLogger("fourd.methods.assembly")

#: The cache entries of finished windows.
STAGE = "assembly-stream"
#: Part of their keys: the windows kept before the seams started from the fitted frame hold
#: another last frame, and must not be resumed from.
SEAMS = "seams from the fitted frame"


def window_spans(count: int, window: int) -> list[tuple[int, int]]:
    """The windows ``(first, stop)`` of a streamed run over ``count`` frames.

    >>> window_spans(7, 3)
    [(0, 3), (3, 6), (6, 7)]
    """
    return [(first, min(first + window, count)) for first in range(0, count, window)]


def reconstruct_streamed(
    source: FrameSource, output, options: Options | None = None
) -> StreamSummary:
    """Animated mesh of ``source`` by ``assembly``, window by window (module docstring),
    written to ``output`` (a fourd ``.npz``, atomically: it appears when every frame is
    written).

    Parameters
    ----------
    source : FrameSource
        The capture, read a window at a time (:func:`fourd.io.frames.open_sequence`).
    output : path-like
        The ``.npz`` to write (:mod:`fourd.io.npz`'s layout; ``rest`` the first frame).
    options : Options
        ``window`` frames per window (0: :data:`~fourd.methods.assembly.options.STREAM_WINDOW`);
        ``paste`` and ``correct`` off; ``anchors`` not a file; ``cache_dir`` keeps every
        finished window.

    Raises
    ------
    InputError
        Too few frames, options a streamed run cannot take, an output that is not ``.npz``, a
        window whose frames give no surface.

    References
    ----------
    004_f87f5acf96d50b57.txt chapter 5 (5.3, 5.6); the windows are this project's (issue 56).
    """
    options = streamable(options or Options(), len(source))
    output = streamed_output(output)
    started = _time.perf_counter()
    with ExitStack() as stack:
        writer, run = None, _Run(source, options)
        for index, written in enumerate(_assembled_windows(run)):
            if writer is None:
                writer = stack.enter_context(
                    npz_frames(
                        output, faces=run.closed_faces, times=source.times, rest=written.vertices[0]
                    )
                )
            writer.write(written.vertices, written.observed)
            log.info(
                "window %d of %d: %.1f s so far",
                index + 1,
                len(run.spans),
                _time.perf_counter() - started,
            )
    seconds = _time.perf_counter() - started
    log.info("assembly, streamed: %d frames in %.1f s", len(source), seconds)
    return StreamSummary(
        output, len(source), run.vertex_count, len(run.spans), run.resumed, seconds
    )


def streamable(options: Options, frames: int) -> Options:
    """``options`` with ``window`` set (0: :data:`STREAM_WINDOW`), after checking that a run
    over ``frames`` frames can go window by window; InputError when it cannot (module
    docstring)."""
    if frames < MIN_FRAMES:
        raise InputError(f"the assembly method needs at least {MIN_FRAMES} frames, got {frames}")
    for name in ("paste", "correct"):
        if getattr(options, name):
            raise InputError(
                f"assembly: {name} changes frames already assembled, which a run in windows "
                f"has written: run the whole sequence at once (without --stream, window=0) or "
                f"set {name}=false"
            )
    if options.anchors not in ANCHOR_SOURCES:
        raise InputError(
            f"assembly: an anchors file ({options.anchors}) is read for the whole sequence: "
            f"run it at once (without --stream, window=0)"
        )
    return dataclasses.replace(options, window=options.window or STREAM_WINDOW)


def assemble_in_windows(seq, options: Options) -> tuple[Block, list[MergeReport]]:
    """The frames of ``seq`` (a :class:`~fourd.sequence.PointCloudSequence`) assembled window
    by window as a streamed run writes them (fitted, holes closed), kept in memory; and the
    merges' reports. ``options`` as :func:`streamable` takes them."""
    options = streamable(options, len(seq))
    run = _Run(FrameSource.of(seq), options)
    windows = list(_assembled_windows(run))
    block = Block(
        windows[0].faces,
        np.concatenate([w.vertices for w in windows]),
        np.concatenate([w.observed for w in windows]),
    )
    return block, run.reports


def _assembled_windows(run: _Run):
    """Each window's frames as written (:meth:`_Run.window`, or read from the cache), in
    order; ``run`` keeps the state between them."""
    source, options, spans = run.source, run.options, run.spans
    cache = StageCache(options.cache_dir)
    key = ""
    if cache.enabled:
        video = None if source.video is None else source.video.fingerprint()
        key = stage_key(
            STAGE,
            SEAMS,
            option_values(options, without=("workers", "scheduler", "cache_dir")),
            source.times,
            video,
        )
    # the first frame's mesh decides the merge processes (its size, as in memory); the first
    # window is read once, here (it has no frames before it to lead with)
    first_read = source.read(*spans[0])
    run.first_mesh = frame_meshes(first_read[:1], options)[0]
    size = len(run.first_mesh[0]) or len(first_read.frames[0].points)
    with ExitStack() as stack:
        pool = stack.enter_context(merge_pool(options.merge_workers(size)))
        bar = stack.enter_context(
            progress(total=len(source) - 1, desc="assembly merges", unit="merge")
        )
        for index, (start, stop) in enumerate(spans):
            lead = run.lead(start)
            read = first_read if index == 0 else source.read(start - lead, stop)
            first_read = None
            seq = read[lead:]
            if cache.enabled:
                key = stage_key(
                    key,
                    index,
                    [stage_key(f.points, f.normals, f.colors, f.faces) for f in seq.frames],
                )
            entry = cache.load(STAGE, key) if cache.enabled else None
            if entry is not None:
                written = run.restore(entry)
                run.resumed += 1
                bar.update(stop - start - (index == 0))
            else:
                if run.resumed and run.resumed == index:
                    report_resumed(log, f"{run.resumed} of {len(spans)} windows")
                written = run.window(read, lead, pool, on_merge=lambda: bar.update(1))
                if cache.enabled:
                    cache.save(STAGE, key, run.entry(written))
            yield written
    if run.resumed == len(spans):
        report_resumed(log, f"all {run.resumed} windows")


class _Run:
    """What goes from one window to the next: the last frame as fitted (the next seam's
    source), the rest fit's and the colour fit's state and the holes' membranes, all made in
    the first frame."""

    def __init__(self, source: FrameSource, options: Options):
        self.source, self.options = source, options
        self.spans = window_spans(len(source), options.window)
        self.resumed = 0
        self.reports: list[MergeReport] = []  # the merges' of the windows assembled here
        self.video_anchors = takes_video_anchors(options, source.video is not None)
        self.last: Block | None = None  # the last frame written, before the holes' membranes
        self.rest_fit: RestFit | None = None
        self.color_fit: ColorFit | None = None
        self.closing: HoleClosing | None = None
        # the first frame as assembled (what the two above come from), and its own mesh
        self.first: Block | None = None
        self.first_mesh = None

    @property
    def closed_faces(self) -> np.ndarray:
        return self.last.faces if self.closing is None else self.closing.output_faces

    @property
    def vertex_count(self) -> int:
        return self.last.vertices.shape[1] if self.closing is None else self.closing.output_count

    def lead(self, start: int) -> int:
        """Frames read before a window starting at frame ``start``: the video's anchors track
        its pairs from two frames before it (the tracking of a pair reuses the images as the
        pair before left them), the seam's pair included."""
        return min(start, 2) if self.video_anchors else 0

    def window(self, read, lead: int, pool, on_merge) -> Block:
        """Assemble the window's frames (``read``, after its first ``lead`` frames) onto the
        frames before: the window's frames as written (colour fit, holes closed)."""
        options, seq, first_window = self.options, read[lead:], self.last is None
        if first_window and self.first_mesh is not None:
            rest = frame_meshes(seq, options, pool, frames=slice(1, None))
            meshes = [self.first_mesh] + rest
        else:
            meshes = frame_meshes(seq, options, pool)
        blocks = base_blocks(seq, meshes)
        guides = self._guides(read, lead, first_window)
        if first_window:
            block, reports = assemble(blocks, options, on_merge=on_merge, pool=pool, guides=guides)
        else:
            block, reports = assemble(
                [self.last] + blocks,
                options,
                on_merge=on_merge,
                pool=pool,
                guides=guides,
                onto=True,
            )
            block = Block(block.faces, block.vertices[1:], block.observed[1:])
        self.reports += reports
        # the colours (from the video, a render per frame) only while the fit can use them
        wanted = options.color_fit and (first_window or self.color_fit is not None)
        colors = frame_colors(seq, meshes) if wanted else None
        if first_window:
            self.first = Block(block.faces, block.vertices[:1], block.observed[:1])
            self._start(meshes, colors)
        vertices = block.vertices.copy()
        if self.rest_fit is not None:
            for t in range(1 if first_window else 0, len(vertices)):
                vertices[t] = self.rest_fit.frame(vertices[t], block.observed[t], meshes[t])
        if self.color_fit is not None and colors is not None:
            for t in range(1 if first_window else 0, len(vertices)):
                fitted = self.color_fit.frame(vertices[t], block.observed[t], meshes[t], colors[t])
                if fitted is not None:
                    vertices[t] = fitted
        # the next seam's map starts from the last frame as fitted: what the fits took back
        # of the chain's slides and wear stays taken back (over 1,000 frames of a sparse
        # take, the drift no longer climbs; benchmarks/METHODS.md), and their corrections
        # start again from nothing
        self.last = Block(block.faces, vertices[-1:].copy(), block.observed[-1:])
        if self.rest_fit is not None:
            self.rest_fit.carried = np.zeros_like(self.rest_fit.carried)
        if self.color_fit is not None:
            self.color_fit.carried = np.zeros_like(self.color_fit.carried)
        written = Block(block.faces, vertices, block.observed)
        return written if self.closing is None else Block(*self.closing.apply(written.vertices, written.observed))

    def _start(self, meshes, colors) -> None:
        """The rest fit, the colour fit and the holes' membranes, from the first frame
        (``meshes`` and their ``colors``: the first window's)."""
        options, first = self.options, self.first
        self._start_rest_fit()
        if colors is not None:
            self.color_fit = ColorFit.start(
                first.vertices[0],
                first.faces,
                first.observed[0],
                meshes[0],
                colors[0],
                radius=options.color_radius,
                scale=options.color_scale,
            )
        if options.close_holes > 0:
            self.closing = holes_to_close(
                first.vertices[0], first.faces, options.close_holes, options.close_smoothness,
                options.open_handles,
            )

    def _start_rest_fit(self) -> None:
        """The rest fit against the first frame as assembled, when ``rest_fit`` is on."""
        options = self.options
        if options.rest_fit:
            self.rest_fit = RestFit(
                self.first.vertices[0],
                self.first.faces,
                iterations=options.rest_fit,
                weight=options.rest_weight,
            )

    def _guides(self, read, lead: int, first_window: bool):
        """The video's anchors of the window's pairs, the seam's pair first (None without):
        tracked over all the frames ``read``, those of the pairs before the seam dropped."""
        if not self.video_anchors:
            return None
        guides = frame_pair_guides(read, self.options)
        return guides if first_window else guides[lead - 1 :]

    def entry(self, written: Block) -> dict[str, np.ndarray]:
        """The cache entry of a finished window: its frames as ``written`` and the state the
        next window starts from."""
        arrays = {
            "vertices": written.vertices,
            "observed": written.observed,
            "faces": self.last.faces,
            "last": self.last.vertices[0],
            "last_observed": self.last.observed[0],
            "first": self.first.vertices[0],
            "first_observed": self.first.observed[0],
        }
        if self.rest_fit is not None:
            arrays["rest_carried"] = self.rest_fit.carried
        if self.color_fit is not None:
            fit = self.color_fit
            arrays |= {
                "color_sample": fit.sample,
                "color_reference": fit.reference,
                "color_edge": np.float64(fit.edge),
                "color_carried": fit.carried,
            }
        return arrays

    def restore(self, entry: dict[str, np.ndarray]) -> Block:
        """The state after a window read from the cache (:meth:`entry`); its frames as written."""
        faces, options = entry["faces"], self.options
        self.last = Block(faces, entry["last"][None], entry["last_observed"][None])
        if self.first is None:
            self.first = Block(faces, entry["first"][None], entry["first_observed"][None])
            if "color_sample" in entry:
                self.color_fit = ColorFit(
                    faces,
                    entry["color_sample"],
                    entry["color_reference"],
                    float(entry["color_edge"]),
                    len(entry["last"]),
                    radius=options.color_radius,
                    scale=options.color_scale,
                )
            self._start_rest_fit()
            if options.close_holes > 0:
                self.closing = holes_to_close(
                    self.first.vertices[0], faces, options.close_holes, options.close_smoothness,
                    options.open_handles,
                )
        if self.rest_fit is not None:
            self.rest_fit.carried = entry["rest_carried"]
        if self.color_fit is not None:
            self.color_fit.carried = entry["color_carried"]
        return Block(faces, entry["vertices"], entry["observed"])
