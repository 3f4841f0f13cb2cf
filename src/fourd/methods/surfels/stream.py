"""``surfels`` over a whole capture with memory bounded by a window of frames (issue 56; the
paper assembles every frame into one model, sec. 3.2, and stopped at 26 frames).

The capture is read ``window`` frames at a time. Each window is assembled as in memory
(preprocessing, seed models, the binary merges) and then merged onto the last frames of the
model before it (:func:`~.assembly.merge` with ``held`` and ``kept``). The past goes on as
the surfels of the mesh only (the window's own surfels cover its frames; carried along, the
others piled up window by window): they are aligned into the window, grown through it by the
hole filling and never dropped by the resampling. Of the past's frames, the first
:data:`HELD` were written and are held in the global optimisations (the acceleration prior
reaches two frames back); the last :data:`LAG` were left unwritten by the window before and
are optimised again with the new frames. The final optimisation (increased rigidity and
acceleration) runs on each window with the same frames held. The seams keep a kink of about
three times the motion's own second difference (benchmarks/METHODS.md, "`surfels`
streamed").

The mesh is that of the first frame's surfels (sec. 3.3), bound once; those surfels keep their
index in every later window, and their rotations from the first frame are composed across
the windows, so each window's frames are carried (:func:`~.meshing.carry_by`), fitted to
their points (``fit_frames``), their small holes closed as in memory (``close_holes``: the
membranes found in the first frame, placed in each frame from its rim) and written as they
come. What the streamed run gives up
against the paper's: a surface first seen after the first window is not in the mesh (the
hole filling cannot reach back into written frames), and the urshape is the first window's.
Memory holds one window and the past's :data:`HELD` + :data:`LAG` frames, plus the output's
observed flags. With video (``video_anchors``) each window tracks the anchors of its own frame
pairs and of the seam's, from the past's last frame. With colours (``color_guide``) the
guides act in each window's merges, its merge onto the past and its final optimisation; the
mesh's surfels keep the reference colours found in the first window
(:func:`.color_guide.reference_colors`), so the guides do not chain from window to window.
With ``cache_dir`` every finished window is kept and a rerun resumes after the last one.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import time as _time
from pathlib import Path

import numpy as np

from fourd.cache import StageCache, cached, option_values, report_resumed, stage_key
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.geometry.hole_closing import HoleClosing, holes_to_close
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.surface_fit import fit_along_normals
from fourd.io.npz import npz_frames
from fourd.methods.base import StreamSummary, run_streamed
from fourd.methods.surfels.anchors import with_video_anchors
from fourd.methods.surfels.assembly import assemble, merge
from fourd.methods.surfels.color_guide import GuideSettings, reference_colors
from fourd.methods.surfels.meshing import (
    Binding,
    align_to_normals,
    bind_vertices,
    carry,
    carry_by,
    mesh_frame,
    observed_vertices,
    surfel_frames,
)
from fourd.methods.surfels.model import (
    Model,
    pack_model,
    surfel_subset,
    unpack_model,
    unsupported_pieces,
)
from fourd.methods.surfels.options import MIN_FRAMES, Options, energy_weights, worker_threads
from fourd.methods.surfels.pipeline import (
    MESH_ONLY,
    assembly_schedule,
    final_optimisation,
    guide_point_colors,
    guide_settings,
    merge_keys,
    meshing_options,
    prepare_frames,
    seed_models,
)
from fourd.methods.surfels.seeds import FramePoints
from fourd.methods.surfels.state import SurfelState
from fourd.methods.surfels.urshape import with_urshape

log = logging.getLogger("fourd.methods.surfels")

#: Frames per window when ``Options.window`` is 0.
STREAM_WINDOW = 16
#: Written frames of the past model a window is merged onto, held (the acceleration prior's
#: reach).
HELD = 2
#: A window's last frames, left unwritten and optimised again with the next window's.
LAG = 2


def reconstruct_streamed(
    source: FrameSource, output, options: Options | None = None
) -> StreamSummary:
    """The ``surfels`` reconstruction of ``source``, window by window, written to ``output``
    (a fourd ``.npz`` animated mesh, atomically: it appears when every frame is written).

    Parameters
    ----------
    source : FrameSource
        The capture, read a window at a time (:func:`fourd.io.frames.open_sequence`).
    output : path-like
        The ``.npz`` to write.
    options : Options
        ``window`` frames per window (0: :data:`STREAM_WINDOW`; at least ``LAG + 1``);
        ``reference`` must be 0;
        ``urshape`` other than ``"off"`` gives the first window's urshape as the ``rest``.

    Raises
    ------
    InputError
        Too few frames, an output that is not ``.npz``, a frame without surface, a
        ``reference`` other than 0, a window shorter than ``LAG + 1``.

    References
    ----------
    Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP
    2007, sec. 3.2-3.3 (``001_3fedd1c3a0ac4198.txt``); the windows are this project's.
    """
    options = options or Options()
    if 0 < options.window <= LAG:
        raise InputError(
            f"surfels, streamed: a window needs at least {LAG + 1} frames, got {options.window}"
        )
    if options.reference != 0:
        raise InputError(
            f"surfels, streamed: the mesh is the first frame's (reference 0), got reference "
            f"{options.reference}"
        )
    return run_streamed(
        "surfels", source, output, MIN_FRAMES, lambda output, work: _run(source, output, options)
    )


@dataclasses.dataclass
class _Carried:
    """The mesh and what carries it from one window to the next: the binding of the first
    frame's mesh to its ``identity`` surfels, their normals there and their rotations from
    it to the last frame written (before the turn onto the normals; None before any)."""

    faces: np.ndarray
    rest: np.ndarray
    binding: Binding
    identity: int
    reference_normals: np.ndarray
    last_frames: np.ndarray | None = None


def _run(source: FrameSource, output: Path, options: Options) -> StreamSummary:
    count, window = len(source), options.window or STREAM_WINDOW
    cache = StageCache(options.cache_dir)
    first = source.read(0, min(window, count))
    spacing = point_spacing(first.frames[0].points)
    sampling = options.sampling * spacing
    noise = options.noise or spacing
    schedule = assembly_schedule(options, noise, sampling)
    final = energy_weights(options, noise, sampling, final=True)
    values = option_values(options, without=("window", "workers", *MESH_ONLY))
    anchored = options.video_anchors and source.video is not None
    salt = (source.video.fingerprint(),) if anchored else ()
    guide = guide_settings(options, sampling)
    tail, tail_frames, key, held = None, [], "", 0
    carried: _Carried | None = None
    closing: HoleClosing | None = None
    resumed = windows = 0
    started = _time.perf_counter()
    with contextlib.ExitStack() as stack:
        out = None
        for start in range(0, count, window):
            stop = min(start + window, count)
            seq = first if start == 0 else source.read(start, stop)
            first = None
            frames, keys = prepare_frames(seq.frames, spacing, options, cache, first=start)
            if anchored:
                tail_frames, frames = _with_anchors(tail_frames, frames, source, start)
                # the merges' keys and the window's carry the video
                keys = [stage_key(k, *salt) if k else "" for k in keys]
            colors = guide_point_colors(seq, frames, options)
            if colors is not None:
                frames = [frame._replace(colors=c) for frame, c in zip(frames, colors, strict=True)]
                # the merges' keys and the window's carry the colours the guides come from
                shade = stage_key(colors)
                keys = [stage_key(k, shade) if k else "" for k in keys]
            local = tail_frames + frames
            kept = 0 if carried is None else carried.identity
            key = stage_key(key, keys, values, held, len(tail_frames)) if cache.enabled else ""
            arrays, was_cached = cached(
                cache,
                "surfels-window",
                key,
                lambda tail=tail, local=local, held=held, kept=kept, keys=keys, guide=guide: (
                    pack_model(
                        _window_model(
                            tail, local, held, kept, keys, sampling, schedule, final, guide,
                            options, cache,
                        )
                    )
                ),
            )
            if was_cached:
                report_resumed(log, f"the window of frames {start}-{stop - 1}")
                resumed += 1
            model = unpack_model(arrays)
            windows += 1
            opening = carried is None
            if opening:
                carried = _first_mesh(model, sampling, options)
                if guide is not None and colors is not None:
                    guide = guide._replace(reference=_mesh_reference(model, local, carried))
            end = len(local) if stop == count else len(local) - LAG
            vertices, observed = _carry_window(carried, model, held, end, options)
            vertices, observed = vertices[: end - held], observed[: end - held]
            if options.fit_frames:
                vertices = fit_along_normals(
                    vertices,
                    carried.faces,
                    [frame.points for frame in local[held:end]],
                    radius=options.fit_radius * spacing,
                    reach=options.fit_reach * spacing,
                ).vertices
            if opening:
                faces, rest = carried.faces, carried.rest
                if options.close_holes > 0:
                    closing = holes_to_close(
                        vertices[0], faces, options.close_holes, options.close_smoothness
                    )
                if closing is not None:
                    faces = closing.output_faces
                    rest = closing.apply(rest[None], np.ones((1, len(rest)), dtype=bool))[1][0]
                out = stack.enter_context(
                    npz_frames(output, faces=faces, times=source.times, rest=rest)
                )
            if closing is not None:
                _, vertices, observed = closing.apply(vertices, observed)
            out.write(vertices, observed)
            log.info(
                "surfels: %d of %d frames written, %d surfels (%.1f s)",
                out.written,
                count,
                model.state.count,
                _time.perf_counter() - started,
            )
            begin = max(0, end - HELD)
            # the past goes on as the mesh's surfels only: the window's own cover its frames,
            # and the others would pile up window by window
            tail = surfel_subset(_frames_of(model, begin), np.arange(carried.identity))
            tail_frames, held = local[begin:], end - begin
    vertex_count = len(carried.rest) if closing is None else closing.output_count
    return StreamSummary(output, count, vertex_count, windows, resumed, 0.0)


def _with_anchors(
    tail_frames: list[FramePoints], frames: list[FramePoints], source: FrameSource, start: int
) -> tuple[list[FramePoints], list[FramePoints]]:
    """The window's ``frames`` (the first one frame ``start``) with the video's anchors into
    the frame after each, and the past's last frame (``tail_frames[-1]``, when there is a past)
    with its anchors into ``start``: the seam's pair is tracked with the window."""
    first = start - 1 if tail_frames else start
    anchored = with_video_anchors(
        tail_frames[-1:] + frames,
        source.times[first : start + len(frames)],
        source.video.select(slice(first, start + len(frames))),
        source.names[first : start + len(frames)],
    )
    if not tail_frames:
        return [], anchored
    return tail_frames[:-1] + anchored[:1], anchored[1:]


def _window_model(
    tail: Model | None,
    local: list,
    held: int,
    kept: int,
    keys: list[str],
    sampling: float,
    schedule,
    final,
    guide: GuideSettings | None,
    options: Options,
    cache: StageCache,
) -> Model:
    """The model of one window: its new frames (after the past's ``local[:len(local) -
    len(keys)]``) assembled, merged onto ``tail`` (the past's last frames, the first ``held``
    of them written; its first ``kept`` surfels, the mesh's, all kept), then the final
    optimisation; the first window's with its urshape when
    ``options.urshape`` asks. With ``guide`` and colours, the colours' guides act in the
    merge onto the past and the final optimisation, the mesh's surfels guided by the
    reference colours carried in ``guide`` (:mod:`.color_guide`)."""
    past = len(local) - len(keys)
    seeds = seed_models(local[past:], range(past, len(local)), sampling, schedule, options)
    seed_keys = [
        stage_key(k, "streamed", index) if k else ""
        for index, k in enumerate(merge_keys(keys, options, cache), start=past)
    ]
    model, _ = assemble(
        seeds, local, schedule, cache=cache, keys=seed_keys, workers=worker_threads(options)
    )
    if tail is not None:
        onto = schedule._replace(guide=guide) if schedule.guide is not None else schedule
        model = merge(tail, model, local, onto, held=held, kept=kept)
    if options.final_iterations:
        model = final_optimisation(
            model,
            local,
            final,
            schedule.match,
            options,
            guide=guide,
            urshape="off" if tail is not None or options.urshape == "off" else "rest",
            held=held,
        )
    return model


def _mesh_reference(model: Model, local: list, carried: _Carried) -> np.ndarray | None:
    """The reference colours [K, 3] of the mesh's ``K`` surfels in the first window's
    ``model`` (:func:`.color_guide.reference_colors`), carried to every later window."""
    reference = reference_colors(
        model.state,
        model.observed,
        [frame.points for frame in local],
        [frame.normals for frame in local],
        [frame.colors for frame in local],
    )
    return None if reference is None else reference[: carried.identity]


def _first_mesh(model: Model, sampling: float, options: Options) -> _Carried:
    """The first window's frame 0 meshed (sec. 3.3) and bound to its surfels; the ``rest`` is
    that mesh, or carried to the window's urshape. The small pieces of the graph that lack
    data in some frame of the window are left out (``min_piece``,
    :func:`.model.unsupported_pieces`); a piece that loses its data in a later window stays."""
    state, meshing = model.state, meshing_options(options)
    keep = np.arange(state.count)
    lost = unsupported_pieces(model, options.min_piece)
    if lost.any() and not lost.all():
        keep = np.flatnonzero(~lost)
    positions, normals = state.positions[0, keep], state.normals[0, keep]
    mesh = mesh_frame(positions, normals, sampling, options=meshing)
    if len(mesh.faces) == 0:
        raise InputError("surfels: the first frame's surfels give no surface to mesh")
    binding = bind_vertices(mesh.vertices, positions, normals, sampling, options=meshing)
    binding = binding._replace(surfel=keep[binding.surfel])
    normals = state.normals[0]
    rest = mesh.vertices
    if model.urshape is not None:
        rest = carry(
            binding, with_urshape(state, model.urshape), 1, align_normals=meshing.align_normals
        )[0]
    return _Carried(mesh.faces, rest, binding, state.count, normals.copy(), np.eye(3)[None])


def _carry_window(
    carried: _Carried, model: Model, held: int, end: int, options: Options
) -> tuple[np.ndarray, np.ndarray]:
    """The frames ``held ..`` of ``model`` (those not written yet): vertices [T, N, 3] and
    observed [T, N] of the first frame's mesh; ``carried.last_frames`` moves on to frame
    ``end - 1``, the last to be written now."""
    state, identity = model.state, carried.identity
    if carried.last_frames is None:  # frame 0 of the model is the mesh's
        frames = surfel_frames(state, 0, align_normals=False)[:, :identity]
    else:
        frames = np.empty((state.frames, identity, 3, 3))
        frames[held - 1] = carried.last_frames
        for t in range(held - 1, state.frames - 1):
            frames[t + 1] = state.rotations[t, :identity] @ frames[t]
    carried.last_frames = frames[end - 1]
    frames = frames[held:]
    meshing = meshing_options(options)
    if meshing.align_normals:
        frames = align_to_normals(
            frames, carried.reference_normals, state.normals[held:, :identity]
        )
    vertices = carry_by(carried.binding, state.positions[held:, :identity], frames)
    observed = observed_vertices(carried.binding, model.observed[held:, :identity], meshing.clip)
    return vertices, observed


def _frames_of(model: Model, begin: int) -> Model:
    """``model`` from its frame ``begin`` on, as frames ``0 ..``."""
    state = model.state
    return Model(
        SurfelState(
            state.positions[begin:], state.normals[begin:], state.rotations[begin:]
        ),
        model.topology,
        0,
        model.observed[begin:],
    )

