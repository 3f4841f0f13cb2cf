"""The ``surfels`` pipeline (Wand et al. 2007, fig. 1): preprocessing of every frame (tensor
voting, normals), a seed model per frame, the iterative model assembly in a binary scheme,
a final global optimisation with increased rigidity and acceleration weights and the
urshape, the animated mesh (sec. 3.3), and (beyond the paper) every frame's vertices fitted
along their normals to that frame's points.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time

import numpy as np

from fourd.animation import AnimatedMesh
from fourd.appearance.color_guide import guide_colors
from fourd.cache import StageCache, cached, option_values, report_resumed, stage_key
from fourd.errors import InputError
from fourd.geometry.hole_closing import close_small_holes
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.surface_fit import fit_along_normals
from fourd.methods.surfels.anchors import with_video_anchors
from fourd.methods.surfels.assembly import Schedule, assemble, optimize_model
from fourd.methods.surfels.color_guide import GuideSettings
from fourd.methods.surfels.energy import Weights
from fourd.methods.surfels.match import MatchOptions
from fourd.methods.surfels.meshing import MeshingOptions, surfel_mesh
from fourd.methods.surfels.model import Model, unsupported_pieces, without_surfels
from fourd.methods.surfels.optimizer import GaussNewtonOptions
from fourd.methods.surfels.options import MIN_FRAMES, Options, energy_weights, worker_threads
from fourd.methods.surfels.part_search import PartSearch
from fourd.methods.surfels.seeds import FramePoints, prepare_frame, seed_model
from fourd.pipeline.worker_threads import map_in_threads
from fourd.progress import progress
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.surfels")

#: Part of every merge's cache key; raised when the merges give other results for the same
#: options and data (fourd's version does not change with the code), so a cache folder from
#: before is not resumed into a run of the new code. 2: the alignments' line search under each
#: step's own association (99bf033); 3: back to the associated line search
#: (experiments/surfels_line_search.py).
MERGES_REVISION = 3


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> AnimatedMesh:
    """Animated mesh from a point-cloud sequence by the surfel-graph reconstruction of Wand
    et al. (SGP 2007).

    Returns an :class:`AnimatedMesh`, one frame per input frame, one connectivity: the mesh of
    frame ``options.reference``'s surfels carried to every frame by the surfel trajectories,
    and to the urshape, which is its ``rest`` (``options.urshape``); ``observed`` is false
    where no surfel near a vertex had data in that frame. Raises
    :class:`InputError` for a sequence too short or without a surface.

    References
    ----------
    Wand, Jenke, Huang, Bokeloh, Guibas, Schilling: Reconstruction of deforming geometry from
    time-varying point clouds, SGP 2007 (``001_3fedd1c3a0ac4198.txt``).
    """
    options = options or Options()
    if len(seq) < MIN_FRAMES:
        raise InputError(f"surfels needs at least {MIN_FRAMES} frames, got {len(seq)}")
    if not -len(seq) <= options.reference < len(seq):
        raise InputError(
            f"reference {options.reference} is not a frame of the {len(seq)} input frames"
        )
    if options.window:
        from fourd.methods.base import streamed_in_memory
        from fourd.methods.surfels.stream import reconstruct_streamed

        return streamed_in_memory(reconstruct_streamed, seq, options, "surfels").result
    started = _time.perf_counter()
    cache = StageCache(options.cache_dir)
    spacing = point_spacing(seq.frames[0].points)
    sampling = options.sampling * spacing
    noise = options.noise or spacing
    frames, keys = prepare_frames(seq.frames, spacing, options, cache)
    salt = ()
    if options.video_anchors and getattr(seq, "video", None) is not None:
        frames = with_video_anchors(frames, seq.times, seq.video, seq.names)
        salt = (seq.video.fingerprint(),)
    colors = guide_point_colors(seq, frames, options)
    if colors is not None:
        frames = [frame._replace(colors=c) for frame, c in zip(frames, colors, strict=True)]
        if options.color_merges:
            salt = (*salt, stage_key(colors))
    schedule = assembly_schedule(options, noise, sampling)
    seeds = seed_models(frames, range(len(frames)), sampling, schedule, options)
    prepared = _time.perf_counter()
    seed_keys = merge_keys(keys, options, cache, *salt)
    # the final pass stands in for the last merge's optimisation only when at least as long
    final_instead = options.final_iterations >= max(options.iterations, 1)
    with progress(total=len(seeds) - 1, desc="surfels: merging", unit="merge") as bar:
        model, _ = assemble(
            seeds, frames, schedule, progress=bar.update, cache=cache, keys=seed_keys,
            workers=worker_threads(options),
            optimise_last=options.last_merge_optimised or not final_instead,
        )
    merged = _time.perf_counter()
    if options.final_iterations:
        model = final_optimisation(
            model,
            frames,
            energy_weights(options, noise, sampling, final=True),
            schedule.match,
            options,
            guide=guide_settings(options, sampling),
            urshape={"off": "off", "rest": "rest"}.get(options.urshape, "joint"),
        )
    optimized = _time.perf_counter()
    lost = unsupported_pieces(model, options.min_piece)
    if lost.any() and not lost.all():
        log.info(
            "surfels: %d surfels in pieces of fewer than %d without data in some frame are "
            "left out of the mesh",
            int(lost.sum()),
            options.min_piece,
        )
        model = without_surfels(model, lost)
    mesh = surfel_mesh(
        model.state,
        sampling,
        reference=options.reference,
        observed=model.observed,
        urshape=model.urshape,
        times=np.asarray(seq.times, dtype=np.float64),
        options=meshing_options(options),
    )
    if options.fit_frames:
        fit = fit_along_normals(
            mesh.vertices,
            mesh.faces,
            [frame.points for frame in frames],
            radius=options.fit_radius * spacing,
            reach=options.fit_reach * spacing,
        )
        mesh = dataclasses.replace(mesh, vertices=fit.vertices)
    if options.close_holes > 0:
        mesh = closed_mesh(mesh, options)
    log.info(
        "surfels: %d frames, %d surfels, %d vertices in %.2f s (preprocessing, anchors and seeds %.2f, "
        "merging %.2f, final optimisation %.2f, meshing and fit %.2f)",
        len(seq),
        model.state.count,
        mesh.vertices.shape[1],
        _time.perf_counter() - started,
        prepared - started,
        merged - prepared,
        optimized - merged,
        _time.perf_counter() - optimized,
    )
    return mesh


def final_optimisation(
    model: Model,
    frames: list,
    weights: Weights,
    match: MatchOptions,
    options: Options,
    *,
    guide: GuideSettings | None,
    urshape: str,
    held: int = 0,
) -> Model:
    """The final global optimisation of ``model`` (sec. 3.2, ``weights`` with the increased
    rigidity and acceleration), then its ``urshape`` (:func:`.assembly.optimize_model`; the
    first ``held`` frames held); where the ``frames`` have colours and with ``guide``,
    ``color_rounds`` times, each with the colours' guides found from where the one before
    left the surfels (:mod:`.color_guide`), the urshape after the last."""
    guided = guide is not None and any(frame.colors is not None for frame in frames)
    rounds = options.color_rounds if guided else 1
    for k in range(rounds):
        model = optimize_model(
            model,
            frames,
            weights,
            solver_options(options, options.final_iterations),
            match,
            urshape=urshape if k == rounds - 1 else "off",
            held=held,
            guide=guide,
        )
    return model


def guide_settings(options: Options, sampling: float) -> GuideSettings | None:
    """The colours' guide's :class:`~.color_guide.GuideSettings` of ``options`` at
    ``eps_sampl`` ``sampling``; None with the guide off."""
    if not options.color_guide or options.color_weight == 0:
        return None
    return GuideSettings(options.color_radius * sampling, options.color_scale * sampling)


def guide_point_colors(seq, frames, options: Options) -> list | None:
    """The colours of the prepared ``frames``' points for the colours' guide
    (:mod:`.color_guide`), from the points' own or the video; None without them or with
    ``color_guide`` off."""
    if not options.color_guide or options.color_weight == 0:
        return None
    return guide_colors(
        seq, [frame.points for frame in frames], [frame.normals for frame in frames]
    )


def prepare_frames(
    frames, spacing: float, options: Options, cache: StageCache, *, first: int = 0
) -> tuple[list[FramePoints], list[str]]:
    """Each of ``frames`` (:class:`~fourd.sequence.Frame`, the first one frame ``first`` of
    the sequence) preprocessed (:func:`.seeds.prepare_frame`: outliers, tensor voting,
    normals) at point spacing ``spacing``, each kept in ``cache``; with their cache keys.
    Frames run side by side on ``options.workers`` threads (:func:`frame_by_frame`). Raises
    :class:`InputError` for a frame without a smooth surface region."""

    def prepare(item) -> tuple[FramePoints, str]:
        index, f = item
        key = (
            stage_key(
                f.points, f.normals, f.sensors, spacing, options.tensor_ratio, options.normals_k
            )
            if cache.enabled
            else ""
        )
        arrays, resumed = cached(
            cache, "surfels-frame", key, lambda: _prepared(f, spacing, options)
        )
        if resumed:
            report_resumed(log, f"frame {index}'s preprocessing")
        if len(arrays["points"]) < 10:
            raise InputError(f"frame {index} has no smooth surface region to start from")
        return FramePoints(arrays["points"], arrays["normals"]), key

    done = frame_by_frame(
        prepare, list(enumerate(frames, start=first)), worker_threads(options),
        "surfels: preprocessing",
    )
    return [frame for frame, _ in done], [key for _, key in done]


def frame_by_frame(function, items: list, workers: int, desc: str) -> list:
    """``[function(item) for item in items]`` with a progress bar (``desc``), on ``workers``
    threads side by side (:func:`fourd.pipeline.worker_threads.map_in_threads`): each item's
    result depends on that item alone, so it is the same either way."""
    done = map_in_threads(function, items, workers)
    return list(progress(done, total=len(items), desc=desc))


def _prepared(frame, spacing: float, options: Options) -> dict:
    """The arrays of :func:`.seeds.prepare_frame` for ``frame`` (a cache entry: the anchors
    are tracked after)."""
    prepared = prepare_frame(
        frame.points,
        frame.normals,
        frame.sensors,
        spacing=spacing,
        max_ratio=options.tensor_ratio,
        k=options.normals_k,
    )
    return {"points": prepared.points, "normals": prepared.normals}


def solver_options(options: Options, iterations: int) -> GaussNewtonOptions:
    """Gauss-Newton options with ``iterations`` steps and ``options``' CG settings."""
    return GaussNewtonOptions(
        iterations=iterations,
        cg_tolerance=options.cg_tolerance,
        cg_iterations=options.cg_iterations,
    )


def assembly_schedule(options: Options, noise: float, sampling: float) -> Schedule:
    """The :class:`~.assembly.Schedule` of the merges for ``options`` at noise level
    ``noise`` and ``eps_sampl`` ``sampling`` (input units)."""
    return Schedule(
        sampling=sampling,
        weights=energy_weights(options, noise, sampling),
        align_data=options.align_data / noise**2,
        align=solver_options(options, options.align_iterations),
        max_stretch=options.max_stretch,
        optimize=solver_options(options, options.iterations),
        fill=solver_options(options, options.fill_iterations),
        match=MatchOptions(tangential=options.linked_tangential),
        urshape=options.urshape == "merges",
        reach=options.merge_reach,
        geodesic=options.geodesic,
        align_percentile=options.align_percentile,
        guide=guide_settings(options, sampling) if options.color_merges else None,
        parts=(
            PartSearch(
                options.part_size * sampling,
                sampling,
                options.part_reach * sampling,
                options.part_gain,
            )
            if options.part_size > 0 and options.part_reach > 0
            else None
        ),
    )


def seed_models(
    frames: list[FramePoints], indices, sampling: float, schedule: Schedule, options: Options
) -> list[Model]:
    """One seed model per frame (:func:`.seeds.seed_model`), frame ``indices[k]`` of the
    assembly's frame list for ``frames[k]``; side by side on ``options.workers`` threads
    (:func:`frame_by_frame`)."""

    def seed(item) -> Model:
        frame, index = item
        return seed_model(
            frame,
            index,
            sampling=sampling,
            weights=schedule.weights,
            gauss_newton_options=schedule.optimize,
            match=MatchOptions(tangential=options.tangential),
            geodesic=options.geodesic,
        )

    return frame_by_frame(
        seed, list(zip(frames, indices, strict=True)), worker_threads(options),
        "surfels: seed regions",
    )


def closed_mesh(mesh: AnimatedMesh, options: Options) -> AnimatedMesh:
    """``mesh`` with its small holes closed (``options.close_holes``,
    :func:`fourd.geometry.hole_closing.close_small_holes`, found in its first frame), the
    membranes placed in every frame and in the ``rest`` from their rims, not observed."""
    vertices, observed = mesh.vertices, mesh.observed
    if mesh.rest is not None:
        vertices = np.concatenate([vertices, mesh.rest[None]])
        observed = np.concatenate([observed, observed[:1]])
    faces, vertices, observed = close_small_holes(
        mesh.faces, vertices, observed, options.close_holes, options.close_smoothness
    )
    frames = mesh.vertices.shape[0]
    return dataclasses.replace(
        mesh,
        faces=faces,
        vertices=vertices[:frames],
        observed=observed[:frames],
        rest=None if mesh.rest is None else vertices[frames],
    )


#: Options that act only on the mesh of a model, not on the model (the cache keys of the
#: merged models and of the streamed windows leave them out).
MESH_ONLY = (
    "mesh_sigma",
    "mesh_cell",
    "mesh_clip",
    "mesh_clip_reference",
    "fit_frames",
    "fit_radius",
    "fit_reach",
    "close_holes",
    "close_smoothness",
    "min_piece",
    "reference",
)

#: Options that do not act on the merges (the cache keys of the merged models leave them out;
#: the last merge's key says itself when that merge is left to the final pass).
NOT_IN_MERGES = (
    *MESH_ONLY,
    "final_rigid",
    "final_accel",
    "final_iterations",
    "last_merge_optimised",
    "color_rounds",
    "window",
    "workers",
)


def merge_keys(keys: list[str], options: Options, cache: StageCache, *salt) -> list[str]:
    """The cache keys of the seed models of frames with preprocessing ``keys``: those and the
    options that act on the merges, and ``salt`` (empty: the in-memory run)."""
    if not cache.enabled:
        return [""] * len(keys)
    without = NOT_IN_MERGES
    if options.urshape != "merges":  # the merges do not use it
        without = (*without, "urshape")
    values = option_values(options, without=without)
    return [stage_key(key, values, MERGES_REVISION, *salt) for key in keys]


def meshing_options(options: Options) -> MeshingOptions:
    """The :class:`~.meshing.MeshingOptions` of ``options``."""
    return MeshingOptions(
        sigma=options.mesh_sigma,
        cell=options.mesh_cell,
        clip=options.mesh_clip,
        clip_reference=options.mesh_clip_reference,
    )
