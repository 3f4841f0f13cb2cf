"""``kinematic`` over a whole capture with memory bounded by a window of frames: frames read
window by window from a :class:`~fourd.frame_source.FrameSource`, each window's 4D fit made
when the sliding reaches it, the sliding carried across windows, and the animated mesh
written to the output frame by frame.

The result is :func:`~fourd.methods.kinematic.reconstruct` with ``window`` set, computed in
another order: the same 4D fits (each window's frames plus ``window_overlap`` on both sides),
the same sliding (its state, the vertices, their motion and the last registration's outcome,
goes from one window to the next), and the trajectory smoothing over the window's frames with
a margin of already slid frames on both sides (:class:`_SeamSmoother`), so no frame is
smoothed against a cut; only the motion test's scale (a median over the frames at hand, not
the whole sequence) differs. What is decided from "the frames" is decided from the first
window's: the template's size and whether sparse frames are densified (and at which density).
With video (``video_anchors``) each window tracks the anchors of its own frame pairs, the
seam's pair from the previous window's last frame included, on the frames as prepared: the
pairs, hence the steps, of the run in memory. The colour guide (``color_guide``) takes the
urshape's colours from the first frame once and carries them across windows; each frame's
point colours are taken when it is prepared, from its own colours when the first window's
frames all have them, else from the video (the run in memory decides from all frames).

Memory holds the frames of about two windows, two 4D fits, the urshape and the output's
observed flags (one byte per vertex and frame); the positions go to the output as they are
final. With ``options.cache_dir`` each finished window is kept (its frames as written and
the state the next window starts from), keyed by the frames read so far and the options, and
a rerun resumes after the last one. Issue 56's 1,000-frame target: ``experiments/long_capture.py``.
"""

from __future__ import annotations

import logging
import time as _time
from contextlib import ExitStack

import numpy as np

from fourd.appearance.color_guide import (
    PhotometricGuides,
    colors_of_cleaned,
    frame_colors_from_video,
)
from fourd.cache import StageCache, report_resumed, stage_key
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.geometry.fans import split_pinches
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.neighbors import point_spacing
from fourd.io.npz import npz_frames, streamed_output
from fourd.methods.base import StreamSummary
from fourd.methods.kinematic.animate import (
    FrameSurfaces,
    slide_settings,
    template_settings,
    urshape_of_field,
)
from fourd.methods.kinematic.field import SpaceTimeField, space_time_points, window_spans
from fourd.methods.kinematic.frames import densify_density, densify_frames, prepare_frames
from fourd.methods.kinematic.mpu4d import fit_mpu4d, mpu_arrays, mpu_from_arrays
from fourd.methods.kinematic.options import MIN_FRAMES, Options
from fourd.methods.kinematic.pipeline import fit_options, video_anchors
from fourd.methods.kinematic.sliding import slide
from fourd.methods.kinematic.trajectories import smooth_trajectories
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.kinematic")

#: Frames per window when ``options.window`` is 0 (issue 56: the whole crane capture at
#: window 20 keeps the dense rig's targets; ``experiments/window_memory.py``).
STREAM_WINDOW = 20
#: The cache entries of finished windows.
STAGE = "kinematic-stream"


def reconstruct_streamed(
    source: FrameSource, output, options: Options | None = None
) -> StreamSummary:
    """Animated mesh of ``source`` by ``kinematic``, window by window, written to ``output``
    (a fourd ``.npz``, atomically: it appears when every frame is written).

    Parameters
    ----------
    source : FrameSource
        The capture, read a window at a time (:func:`fourd.io.frames.open_sequence`).
    output : path-like
        The ``.npz`` to write (:mod:`fourd.io.npz`'s layout; ``rest`` the urshape).
    options : Options
        ``window`` frames per window (0: :data:`STREAM_WINDOW`); ``times`` must be empty (one
        output frame per input frame); ``cache_dir`` keeps every finished window.

    Raises
    ------
    InputError
        Too few frames, output times asked for, an output that is not ``.npz``, a bad frame.

    References
    ----------
    000_00387fefe94cc850.txt sections 2-5; the windows are this project's (issue 56).
    """
    options = options or Options()
    output = streamed_output(output)
    if len(source) < MIN_FRAMES:
        raise InputError(f"kinematic needs at least {MIN_FRAMES} frames, got {len(source)}")
    if options.times:
        raise InputError("a streamed run writes one frame per input frame (times must be empty)")
    started = _time.perf_counter()
    cache = StageCache(options.cache_dir)
    spans = window_spans(source.times, options.window or STREAM_WINDOW, options.window_overlap)
    run = _Run(source, options)
    video = source.video.fingerprint() if run.uses_video else None
    key = stage_key(STAGE, options, source.times, video) if cache.enabled else ""
    resumed = 0
    with ExitStack() as stack:
        writer = None
        for index, span in enumerate(spans):
            frame_keys = run.frames.read_through(span.fit_last, keys=cache.enabled)
            key = stage_key(key, index, frame_keys) if cache.enabled else ""
            entry = cache.load(STAGE, key) if cache.enabled else None
            if entry is not None:
                written = run.restore(entry, span)
                resumed += 1
            else:
                if resumed and resumed == index:
                    report_resumed(log, f"{resumed} of {len(spans)} windows")
                written = run.window(index, span, final=index == len(spans) - 1)
                if cache.enabled:
                    cache.save(STAGE, key, run.entry(written))
            if writer is None:
                # one copy of a pinched vertex per fan, as in memory (pipeline.without_pinches)
                faces, copies = split_pinches(run.faces, len(run.rest))
                writer = stack.enter_context(
                    npz_frames(output, faces=faces, times=source.times, rest=run.rest[copies])
                )
            writer.write(*(array[:, copies] for array in written))
            if index + 1 < len(spans):
                after = spans[index + 1]
                # the sliding starts from the frame before, the anchors' tracking one earlier
                run.frames.forget_before(min(after.fit_first, after.first - 2))
            log.info(
                "window %d of %d (frames %d-%d): %.1f s so far",
                index + 1,
                len(spans),
                span.first,
                span.last,
                _time.perf_counter() - started,
            )
    if resumed == len(spans):
        report_resumed(log, f"all {resumed} windows")
    seconds = _time.perf_counter() - started
    log.info("kinematic, streamed: %d frames in %.1f s", len(source), seconds)
    return StreamSummary(output, len(source), len(run.rest), len(spans), resumed, seconds)


class _Run:
    """What goes from one window to the next: the urshape and the settings the first window
    fixed, the last window's 4D fit, the sliding's state and the smoother's frames."""

    def __init__(self, source: FrameSource, options: Options):
        self.options, self.times = options, source.times
        self.video = source.video if options.video_anchors else None
        self.time_unit = float(np.median(np.diff(self.times)))
        self.frames = _Frames(source, options)
        self.smoother = _SeamSmoother(options)
        self.rest = self.faces = None
        self.colour_reference = None  # the urshape's log colours (the colour guide)
        self.spacing = self.bandwidth = 0.0
        self.fit = None  # (span, MPU4D) of the previous window
        self.state = None

    @property
    def uses_video(self) -> bool:
        """Whether the video can change the result (its anchors or its colours)."""
        video = self.frames.source.video is not None
        return video and (self.options.video_anchors or self.options.color_guide)

    @property
    def delta(self) -> float:
        return self.spacing * self.options.time_scale

    def window(self, index: int, span, *, final: bool):
        """Fit, slide and smooth window ``index``: the frames it gives out ``(vertices [k, N,
        3], observed [k, N])``."""
        options, frames, times = self.options, self.frames, self.times
        if index == 0:
            self.spacing = point_spacing(frames.points(0), seed=options.seed)
        fit_frames = range(span.fit_first, span.fit_last + 1)
        stride = options.fit_stride
        stp = space_time_points(
            [frames.points(i)[::stride] for i in fit_frames],
            [frames.normals(i)[::stride] for i in fit_frames],
            times[span.fit_first : span.fit_last + 1],
            delta=self.delta,
            time_origin=times[0],
            time_unit=self.time_unit,
        )
        mpu_options = fit_options(options, self.spacing)
        fits = [
            *([self.fit] if self.fit else []),
            (span, fit_mpu4d(stp.points, stp.normals, options=mpu_options)),
        ]
        del stp
        field = SpaceTimeField(
            [(s.start, s.stop) for s, _ in fits],
            lambda i: fits[i][1],
            time_origin=times[0],
            time_scale=self.delta / self.time_unit,
        )
        if index == 0:
            points = [frames.points(i) for i in fit_frames]
            normals = [frames.normals(i) for i in fit_frames]
            box, _, cell, self.bandwidth = template_settings(points, self.spacing, options)
            self.rest, self.faces = urshape_of_field(
                field, points, normals, times, box, cell, self.bandwidth, options, False
            )
            del points, normals
            log.info("urshape: %d vertices", len(self.rest))
            self.smoother.reference = self.rest
        slid = range(span.first if index == 0 else span.first - 1, span.last + 1)
        data = [frames.points(i) for i in slid]
        with_surface = [k if options.data_term and len(data[k]) else -1 for k in range(len(data))]
        with_surface[0] = -1  # the urshape, or the previous window's last frame
        normals = [frames.normals(i) for i in slid]
        result = slide(
            self.rest,
            self.faces,
            field,
            times[slid.start : slid.stop],
            options=slide_settings(options, self.rest, self.faces, self.spacing),
            data=data,
            surfaces=FrameSurfaces(with_surface, data, normals, self.bandwidth),
            return_steps=True,
            start=self.state,
            anchors=self._anchors(slid),
            colour_guides=self._colour_guides(index, slid, with_surface, data, normals),
        )
        self.state, self.fit = result.state, fits[-1]
        new = slice(0, None) if index == 0 else slice(1, None)
        return self.smoother.push(
            result.animation.vertices[new],
            result.animation.observed[new],
            times[span.first : span.last + 1],
            final=final,
        )

    def _anchors(self, slid: range) -> list | None:
        """The sliding's anchors over frames ``slid`` from the video (None without), one entry
        per frame: the tracks from the frame before (None for the first). The tracking starts
        a frame earlier where there is one: a pair reuses its first frame's images as the
        pair before left them, so this is how the run in memory tracks them."""
        if self.video is None:
            return None
        first = max(slid.start - 1, 0)
        frames = range(first, slid.stop)
        tracked = video_anchors(
            [self.frames.points(i) for i in frames],
            self.times[first : slid.stop],
            self.video.select(slice(first, slid.stop)),
            self.options,
        )
        pairs = tracked.pairs[slid.start - first :]
        return [None] + [(p.source, p.target, p.confidence) for p in pairs]

    def _colour_guides(self, index: int, slid: range, with_surface, data, normals):
        """The colour guides of the sliding over frames ``slid`` (None without colours): the
        urshape's colours from the first frame's in the first window, kept for the rest."""
        if not self.options.color_guide:
            return None
        colors = [self.frames.colors(i) for i in slid]
        if index == 0 and colors[0] is None:
            return None
        if index > 0 and self.colour_reference is None:
            return None
        edge = median_edge_length(self.rest, self.faces)
        guides = PhotometricGuides(
            self.rest,
            self.faces,
            with_surface,
            data,
            normals,
            colors,
            radius=self.options.color_radius * edge,
            scale=self.options.color_scale * edge,
            reference=self.colour_reference,
        )
        self.colour_reference = guides.reference
        return guides

    def entry(self, written) -> dict[str, np.ndarray]:
        """The cache entry of a finished window: the frames it gave out and everything
        :meth:`restore` needs to go on after it."""
        arrays = {
            "written_vertices": written[0],
            "written_observed": written[1],
            "rest": self.rest,
            "faces": self.faces,
            "settings": np.array([self.spacing, self.bandwidth, self.frames.density]),
            "colour_source": np.array(self.frames.colour_source or ""),
            **(
                {} if self.colour_reference is None else {"colour_reference": self.colour_reference}
            ),
            **{f"state_{k}": v for k, v in self.state.items()},
            **{f"fit_{k}": v for k, v in mpu_arrays(self.fit[1]).items()},
            **{f"smoother_{k}": v for k, v in self.smoother.buffer().items()},
        }
        return arrays

    def restore(self, entry, span):
        """Go on after the window whose :meth:`entry` is ``entry``; its written frames."""
        self.rest, self.faces = entry["rest"], entry["faces"]
        self.spacing, self.bandwidth, self.frames.density = (float(v) for v in entry["settings"])
        if "colour_source" in entry:  # entries written before the colour guide streamed lack it
            self.frames.colour_source = str(entry["colour_source"]) or None
            self.frames.colour_decided = True
        self.colour_reference = entry.get("colour_reference")
        self.state = {k[6:]: v for k, v in entry.items() if k.startswith("state_")}
        self.fit = (
            span,
            mpu_from_arrays({k[4:]: v for k, v in entry.items() if k.startswith("fit_")}),
        )
        self.smoother.reference = self.rest
        self.smoother.restore({k[9:]: v for k, v in entry.items() if k.startswith("smoother_")})
        return entry["written_vertices"], entry["written_observed"]


class _Frames:
    """The frames of the windows in use: read from the source in order (kept raw until a
    window needs them prepared), prepared (and, when sparse, densified) on first use, and
    forgotten once no later window needs them."""

    def __init__(self, source: FrameSource, options: Options):
        self.source, self.options = source, options
        self.raw: dict = {}
        self.prepared: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.colored: dict[int, np.ndarray | None] = {}
        self.next = 0
        self.density: float | None = None
        #: Where the colour guide's point colours come from: "own", "video" or None (no
        #: colours, or no colour guide); the first window's frames decide.
        self.colour_source: str | None = None
        self.colour_decided = not options.color_guide

    def read_through(self, last: int, *, keys: bool) -> list[str]:
        """Read frames up to ``last``; the cache keys of those read now (when ``keys``)."""
        if last < self.next:
            return []
        part = self.source.read(self.next, last + 1)
        for k, frame in enumerate(part):
            self.raw[self.next + k] = frame
        self.next = last + 1
        return [stage_key(f.points, f.normals, f.sensors) for f in part] if keys else []

    def forget_before(self, first: int) -> None:
        for store in (self.raw, self.prepared, self.colored):
            for index in [i for i in store if i < first]:
                del store[index]

    def _prepare(self) -> None:
        """Prepare every raw frame held (two at a time: :func:`prepare_frames`)."""
        indices = sorted(self.raw)
        part = PointCloudSequence(tuple(self.raw[i] for i in indices))
        points, normals = prepare_frames(part, self.options)
        surface = None
        if self.density is None:  # the first window decides (densify_frames)
            self.density, surface = densify_density(points, normals, self.options)
        # the raw frames held are always consecutive: read in order, forgotten from the front
        points, normals = densify_frames(
            points, normals, self.options, density=self.density, first=indices[0], surface=surface
        )
        if not self.colour_decided:
            self.colour_source = _colour_source([self.raw[i] for i in indices], self.source.video)
            self.colour_decided = True
        for i, p, n in zip(indices, points, normals, strict=True):
            self.prepared[i] = (p, n)
            self.colored[i] = self._colors(i, p, n)
        self.raw.clear()

    def _colors(self, index: int, points, normals) -> np.ndarray | None:
        """The colours [P, 3] of frame ``index``'s prepared ``points`` (as the run in memory
        takes them, :func:`fourd.appearance.color_guide.frame_colors_from_video`)."""
        if self.colour_source == "own":
            frame = self.raw[index]
            return colors_of_cleaned(frame.points, frame.colors, points)
        if self.colour_source == "video":
            one = PointCloudSequence(
                (self.raw[index],), (), self.source.video.select(slice(index, index + 1))
            )
            return frame_colors_from_video(one, 0, points, normals)
        return None

    def points(self, index: int) -> np.ndarray:
        if index not in self.prepared:
            self._prepare()
        return self.prepared[index][0]

    def normals(self, index: int) -> np.ndarray:
        if index not in self.prepared:
            self._prepare()
        return self.prepared[index][1]

    def colors(self, index: int) -> np.ndarray | None:
        if index not in self.prepared:
            self._prepare()
        return self.colored[index]


def _colour_source(frames, video) -> str | None:
    """Where the point colours of a run whose first frames are ``frames`` come from: their
    own when they all have colours or there is no video, else the video; None when neither."""
    own = [f.colors is not None for f in frames]
    if all(own) or video is None:
        return "own" if any(own) else None
    return "video"


class _SeamSmoother:
    """:func:`smooth_trajectories` over a sequence that arrives a window at a time: each
    push smooths the frames not yet written together with ``margin`` frames already written
    before them, and gives out those with ``margin`` frames after them (all at the end). The
    filter's reach is ``passes`` frames (twice that with the motion test), so the margin of
    ``2 passes + 2`` frames keeps the cut out of every frame given out."""

    def __init__(self, options: Options):
        self.passes = options.temporal_smoothing
        self.motion = options.smoothing_motion
        self.margin = 2 * self.passes + 2
        self.reference = None
        self.vertices = self.observed = self.times = None
        self.done = 0  # frames of the buffer already given out

    def push(self, vertices, observed, times, *, final: bool):
        """Add slid frames; the frames now final ``(vertices [k, N, 3], observed [k, N])``."""
        if self.vertices is None:
            self.vertices, self.observed, self.times = vertices, observed, np.asarray(times)
        else:
            self.vertices = np.concatenate([self.vertices, vertices])
            self.observed = np.concatenate([self.observed, observed])
            self.times = np.concatenate([self.times, times])
        end = len(self.vertices) if final else len(self.vertices) - self.margin
        if end <= self.done:
            return self.vertices[:0], self.observed[:0]
        smoothed = smooth_trajectories(
            self.vertices,
            self.times,
            self.passes,
            motion_threshold=self.motion,
            reference=self.reference,
        )
        out = smoothed[self.done : end], self.observed[self.done : end]
        keep = max(0, end - self.margin)
        self.vertices, self.observed, self.times = (
            self.vertices[keep:],
            self.observed[keep:],
            self.times[keep:],
        )
        self.done = end - keep
        return out

    def buffer(self) -> dict[str, np.ndarray]:
        return {
            "vertices": self.vertices,
            "observed": self.observed,
            "times": self.times,
            "done": np.array(self.done),
        }

    def restore(self, arrays) -> None:
        self.vertices, self.observed, self.times = (
            arrays["vertices"],
            arrays["observed"],
            arrays["times"],
        )
        self.done = int(arrays["done"])
