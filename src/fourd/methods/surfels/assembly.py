"""Iterative model assembly (sec. 3.2): adjacent frame ranges merged in a binary scheme
until one model spans every frame. One merge:

1. *alignment* of the left range's last frame to the right range's first and of the right's
   first to the left's last (:func:`.align.align_ranges`); the one with less stretch is kept;
2. *stitching*: the surfels of both ranges connected from scratch within ``eps_top`` in the
   aligned frame (the other range's surfels are then carried into it by the hole filling,
   the paper's third alignment "along the established correspondences");
3. *hole filling*: the left surfels grown forward through the right frames and the right ones
   backward through the left frames (:func:`.fill.fill_holes`);
4. *resampling* to ``eps_sampl`` (:func:`.resample.redundant_surfels`) and the topology
   rebuilt with the stretch filter (edges whose length changes by more than ``max_stretch``
   over the trajectories are rejected);
5. *global optimisation* of all trajectories of the merged range with the full energy, then,
   when the schedule asks, of the trajectories together with the range's urshape (computed
   from scratch at each level, :mod:`.urshape`).

References
----------
Wand et al.: Reconstruction of deforming geometry from time-varying point clouds, SGP 2007,
section 3.2 (``001_3fedd1c3a0ac4198.txt``).
"""

from __future__ import annotations

import dataclasses
import logging
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from typing import NamedTuple

import numpy as np

from fourd.cache import NO_CACHE, StageCache, cached, report_resumed, stage_key
from fourd.methods.surfels.align import align_ranges
from fourd.methods.surfels.anchors import pair_anchors
from fourd.methods.surfels.color_guide import GuideData, GuideSettings, color_guides
from fourd.methods.surfels.energy import Weights
from fourd.methods.surfels.fill import fill_holes
from fourd.methods.surfels.match import MatchOptions, frame_data
from fourd.methods.surfels.model import Model, observed_surfels, pack_model, unpack_model
from fourd.methods.surfels.motion import fit_rotations
from fourd.methods.surfels.optimizer import GaussNewtonOptions, free_unknowns, gauss_newton
from fourd.methods.surfels.part_search import PartSearch
from fourd.methods.surfels.resample import redundant_surfels
from fourd.methods.surfels.state import SurfelState, layout
from fourd.methods.surfels.topology import build_topology
from fourd.methods.surfels.urshape import fit_urshape
from fourd.pipeline.merge_tree import merge_tree
from fourd.pipeline.worker_threads import concurrent_kernels_safe

log = logging.getLogger("fourd.methods.surfels.assembly")


class Schedule(NamedTuple):
    """What each stage of a merge runs with.

    sampling : float
        ``eps_sampl`` (input units).
    weights : Weights
        Eq. (3) during the merging.
    align_data : float
        Data weight per surfel in the alignment.
    max_stretch : float
        Stitching filter.
    align, optimize, fill : GaussNewtonOptions
        The alignment, the global optimisation of a merged range and the local one of a filled
        frame.
    match : MatchOptions
        The data term's association outside the alignment (the ``"global"`` regime).
    urshape : bool
        Each merge ends with the urshape's optimisation (the paper's schedule).
    reach : int
        Frames on each side of the seam that a merge's global optimisation moves
        (:func:`optimize_near_seam`); 0, or with ``urshape``: every frame.
    geodesic : bool
        The topology flags the edges within ``eps_top`` along the surface, judged by their
        normals, for the shape priors (:func:`.topology.build_topology`); false: every edge
        serves every prior.
    align_percentile : float
        The alignment's cutoff percentile (:func:`.align.align_ranges`).
    parts : PartSearch or None
        The alignment's rigid search per part (:mod:`.part_search`); None: none.
    guide : GuideSettings or None
        The colours' guides in each merge's global optimisation, where the frames have
        colours (:mod:`.color_guide`); None: none.
    """

    sampling: float
    weights: Weights
    align_data: float
    max_stretch: float
    align: GaussNewtonOptions
    optimize: GaussNewtonOptions
    fill: GaussNewtonOptions
    match: MatchOptions
    urshape: bool = False
    reach: int = 0
    geodesic: bool = True
    align_percentile: float = 100.0
    parts: PartSearch | None = None
    guide: GuideSettings | None = None


def range_data(frames: list, start: int, stop: int):
    """:class:`~.match.Data` of frames ``start .. stop - 1`` (indices relative to ``start``),
    with the anchors between them."""
    return frame_data(
        [frames[t].points for t in range(start, stop)],
        normals=[frames[t].normals for t in range(start, stop)],
        anchors=pair_anchors([frames[t].forward for t in range(start, stop - 1)]),
    )


def optimize_model(
    model: Model,
    frames: list,
    weights: Weights,
    options: GaussNewtonOptions,
    match: MatchOptions | None = None,
    *,
    urshape: str = "off",
    held: int = 0,
    guide: GuideSettings | None = None,
) -> Model:
    """Global optimisation of all trajectories of ``model`` against its frames' data; then,
    with ``urshape`` ``"joint"``, of the trajectories together with the urshape, or with
    ``"rest"`` of the urshape alone (:func:`.fit_urshape`, the same weights and options; the
    model's earlier urshape is not used); ``"off"``: none. The first ``held`` frames stay as
    they are, boundary conditions of the others (the streamed run's seam, :mod:`.stream`;
    only with ``urshape`` ``"off"``). With ``guide``, the colours' guides of the model's
    surfels at its state join the data where the frames have colours (:mod:`.color_guide`)."""
    if held and urshape != "off":
        raise ValueError("held frames and an urshape do not go together")
    data = dataclasses.replace(
        range_data(frames, model.start, model.stop), guides=model_guides(model, frames, guide)
    )
    free = None
    if held:
        moving = np.ones((model.state.frames, model.state.count), dtype=bool)
        moving[:held] = False
        free = free_unknowns(layout(model.state), moving)
    result = gauss_newton(model.state, model.topology, data, weights, match, options, free=free)
    log.debug(
        "frames %d-%d, %d surfels: energy %.4g -> %.4g in %d steps (CG %s)",
        model.start,
        model.stop - 1,
        model.state.count,
        result.energies[0],
        result.energies[-1],
        len(result.cg_iterations),
        result.cg_iterations.tolist(),
    )
    state, rest = result.state, None
    if urshape != "off":
        fitted = fit_urshape(
            state, model.topology, data, weights, match, options, joint=urshape == "joint"
        )
        state, rest = fitted.state, fitted.urshape
        energies = fitted.optimization.energies
        log.debug("urshape: energy %.4g -> %.4g", energies[0], energies[-1])
    observed = observed_surfels(state, data, model.topology.radius)
    return Model(state, model.topology, model.start, observed, rest)


def model_guides(model: Model, frames: list, guide: GuideSettings | None) -> GuideData | None:
    """The colours' guides (:func:`.color_guide.color_guides`) of ``model``'s surfels in its
    frames of ``frames`` (:class:`~.seeds.FramePoints` with ``colors``); None without
    ``guide`` or colours."""
    own = frames[model.start : model.stop]
    if guide is None or all(frame.colors is None for frame in own):
        return None
    return color_guides(
        model.state,
        model.observed,
        [frame.points for frame in own],
        [frame.normals for frame in own],
        [frame.colors for frame in own],
        guide,
    )


def optimize_near_seam(
    model: Model,
    frames: list,
    seam: int,
    reach: int,
    weights: Weights,
    options: GaussNewtonOptions,
    match: MatchOptions | None = None,
) -> Model:
    """The global optimisation of a merged ``model`` where the merge changed it most: frames
    ``seam - reach .. seam + reach - 1`` (``seam`` the right range's first frame, relative to
    ``model.start``) move, their neighbours in time are held as boundary conditions (the
    rigidity and acceleration terms reach one and two frames), the frames beyond are left as
    the hole filling made them. The issue's "solving only where things changed"; the paper
    optimises every frame (:func:`optimize_model`)."""
    state, count = model.state, model.state.count
    first, stop = max(0, seam - reach), min(state.frames, seam + reach)
    start, end = max(0, first - 2), min(state.frames, stop + 2)
    local = SurfelState(
        state.positions[start:end], state.normals[start:end], state.rotations[start : end - 1]
    )
    moving = np.zeros((end - start, count), dtype=bool)
    moving[first - start : stop - start] = True
    data = range_data(frames, model.start + start, model.start + end)
    result = gauss_newton(
        local, model.topology, data, weights, match, options,
        free=free_unknowns(layout(local), moving),
    )
    log.debug(
        "frames %d-%d of %d-%d, %d surfels: energy %.4g -> %.4g in %d steps",
        model.start + first, model.start + stop - 1, model.start, model.stop - 1, count,
        result.energies[0], result.energies[-1], len(result.cg_iterations),
    )
    positions, normals = state.positions.copy(), state.normals.copy()
    rotations = state.rotations.copy()
    positions[start:end], normals[start:end] = result.state.positions, result.state.normals
    rotations[start : end - 1] = result.state.rotations
    merged = SurfelState(positions, normals, rotations)
    observed = observed_surfels(
        merged, range_data(frames, model.start, model.stop), model.topology.radius
    )
    return Model(merged, model.topology, model.start, observed)


def merge(
    left: Model,
    right: Model,
    frames: list,
    schedule: Schedule,
    *,
    held: int = 0,
    kept: int = 0,
    optimise: bool = True,
) -> Model:
    """Merge two adjacent ranges (``left.stop == right.start``) into one model over both
    (sec. 3.2: align, stitch, fill holes, resample, optimise). With ``optimise`` false the
    merged model is returned before its global optimisation (the last merge, when a final
    pass optimises every frame next).

    For the streamed run (:mod:`.stream`), where the left range is the past: its first
    ``held`` frames are held in the global optimisation, and its first ``kept`` surfels are
    never dropped by the resampling, so they stay first and in their order (a surfel's index
    still names it)."""
    if left.stop != right.start:
        raise ValueError(
            f"ranges must be adjacent, got {left.start}-{left.stop} and {right.start}-{right.stop}"
        )
    # alignment both ways; the one with less stretch is kept (sec. 3.2)
    first, last = frames[right.start], frames[left.stop - 1]
    forward = align_ranges(
        left,
        first.points,
        first.normals,
        schedule.weights,
        schedule.align,
        data_weight=schedule.align_data,
        percentile=schedule.align_percentile,
        parts=schedule.parts,
        anchors=last.forward,
    )
    backward = align_ranges(
        _first_frame(right),
        last.points,
        last.normals,
        schedule.weights,
        schedule.align,
        data_weight=schedule.align_data,
        percentile=schedule.align_percentile,
        parts=schedule.parts,
        anchors=None if last.forward is None else last.forward.reversed(),
    )
    ahead = forward.stretch <= backward.stretch
    nl, nr = left.state.frames, right.state.frames
    sl, sr = left.state.count, right.state.count
    frames_count, count = nl + nr, sl + sr
    positions = np.zeros((frames_count, count, 3))
    normals = np.zeros((frames_count, count, 3))
    rotations = np.broadcast_to(np.eye(3), (frames_count - 1, count, 3, 3)).copy()
    known = np.zeros((frames_count, count), dtype=bool)
    positions[:nl, :sl], normals[:nl, :sl] = left.state.positions, left.state.normals
    rotations[: nl - 1, :sl] = left.state.rotations
    known[:nl, :sl] = True
    positions[nl:, sl:], normals[nl:, sl:] = right.state.positions, right.state.normals
    rotations[nl:, sl:] = right.state.rotations
    known[nl:, sl:] = True
    if ahead:  # the left surfels carried into the right's first frame
        positions[nl, :sl], normals[nl, :sl] = forward.positions, forward.normals
        rotations[nl - 1, :sl] = forward.rotations
        known[nl, :sl] = True
    else:  # the right surfels carried back into the left's last frame
        positions[nl - 1, sl:], normals[nl - 1, sl:] = backward.positions, backward.normals
        rotations[nl - 1, sl:] = np.swapaxes(backward.rotations, -1, -2)
        known[nl - 1, sl:] = True
    log.debug("alignment stretch: forward %.3g, backward %.3g", forward.stretch, backward.stretch)
    # copies of the nearest known frame, so that nothing undefined enters an energy
    for t in range(nl, frames_count):
        unknown = ~known[t, :sl]
        positions[t, :sl][unknown] = positions[t - 1, :sl][unknown]
        normals[t, :sl][unknown] = normals[t - 1, :sl][unknown]
    for t in range(nl - 1, -1, -1):
        unknown = ~known[t, sl:]
        positions[t, sl:][unknown] = positions[t + 1, sl:][unknown]
        normals[t, sl:][unknown] = normals[t + 1, sl:][unknown]
    # stitching: from scratch within eps_top in the aligned frame
    radius = 2.0 * schedule.sampling
    aligned_frame = nl if ahead else nl - 1
    stitched = build_topology(
        positions,
        radius,
        reference=aligned_frame,
        max_stretch=None,
        normals=normals if schedule.geodesic else None,
    )
    state = fill_holes(
        SurfelState(positions, normals, rotations),
        known,
        stitched,
        frames[left.start : right.stop],
        schedule.weights,
        schedule.fill,
        schedule.match,
    )
    # resampling: keep the surfels with data in the most frames
    observed = np.zeros((frames_count, count), dtype=bool)
    observed[:nl, :sl] = left.observed
    observed[nl:, sl:] = right.observed
    priority = observed.sum(axis=0)
    priority[:kept] += frames_count + 1
    drop = redundant_surfels(state.positions, 0.5 * schedule.sampling, priority=priority)
    drop[:kept] = False
    keep = np.flatnonzero(~drop)
    topology = build_topology(
        state.positions[:, keep],
        radius,
        reference=aligned_frame,
        max_stretch=schedule.max_stretch,
        normals=state.normals[:, keep] if schedule.geodesic else None,
    )
    resampled = SurfelState(
        state.positions[:, keep],
        state.normals[:, keep],
        fit_rotations(state.positions[:, keep], topology),
    )
    log.debug(
        "merged %d-%d: %d + %d surfels -> %d, %d edges",
        left.start,
        right.stop - 1,
        sl,
        sr,
        len(keep),
        len(topology.edges),
    )
    model = Model(resampled, topology, left.start, observed[:, keep])
    if not optimise:
        return model
    if held:
        return optimize_model(
            model, frames, schedule.weights, schedule.optimize, schedule.match, held=held,
            guide=schedule.guide,
        )
    if schedule.reach and not schedule.urshape and frames_count > 2 * schedule.reach + 2:
        return optimize_near_seam(
            model, frames, nl, schedule.reach, schedule.weights, schedule.optimize, schedule.match
        )
    return optimize_model(
        model, frames, schedule.weights, schedule.optimize, schedule.match,
        urshape="joint" if schedule.urshape else "off", guide=schedule.guide,
    )


def _first_frame(model: Model) -> Model:
    """``model`` cut to its first frame (the right range, aligned backwards)."""
    state = model.state
    return Model(
        SurfelState(state.positions[:1], state.normals[:1], state.rotations[:0]),
        model.topology,
        model.start,
        model.observed[:1],
    )


def assemble(
    models: list[Model],
    frames: list,
    schedule: Schedule,
    *,
    progress=None,
    cache: StageCache = NO_CACHE,
    keys: list[str] | None = None,
    workers: int = 1,
    optimise_last: bool = True,
) -> tuple[Model, str]:
    """Merge adjacent ``models`` (consecutive ranges, e.g. one seed model per frame) pairwise,
    level by level, until one spans them all (sec. 3.2 "Iteration", :func:`fourd.pipeline.merge_tree.merge_tree`);
    ``progress`` is called with the number of merges done after each. With a ``cache`` and
    one key per model, each merged model is kept there under the hash of its two parts' keys
    and the schedule, so a rerun resumes after the last finished merge. Returns the model and
    its key. With ``optimise_last`` false the last merge skips its global optimisation
    (:func:`merge`), for a caller whose final pass optimises every frame next.

    ``workers`` merges run side by side in threads, each as soon as its two parts are there
    (beyond the paper, which merged one after another). A merge depends on its two parts
    alone, so the result is the same for any ``workers``; the threads overlap what one merge
    leaves single-threaded (scipy's sparse products, the Python between kernels). One after
    another where numba's threading layer cannot run two parallel kernels at once
    (``workqueue``). An interrupted run stops after the merges already running."""
    keys = list(keys) if keys is not None else [""] * len(models)
    plan = merge_tree(len(models))
    optimised = [optimise_last or k < len(plan) - 1 for k in range(len(plan))]
    for k, (a, b) in enumerate(plan):
        salt = () if optimised[k] else ("not optimised",)
        keys.append(stage_key(keys[a], keys[b], schedule, *salt) if cache.enabled else "")
    nodes: dict[int, Model] = dict(enumerate(models))
    root = len(models) + len(plan) - 1 if plan else 0

    def run(k: int, left: Model, right: Model) -> Model:
        arrays, resumed = cached(
            cache,
            "surfels-merge",
            keys[len(models) + k],
            lambda: pack_model(merge(left, right, frames, schedule, optimise=optimised[k])),
        )
        if resumed:
            report_resumed(log, f"the merge of frames {left.start}-{right.stop - 1}")
        return unpack_model(arrays)

    def finished(k: int, model: Model) -> None:
        a, b = plan[k]
        del nodes[a], nodes[b]
        nodes[len(models) + k] = model
        if progress is not None:
            progress(1)

    if workers <= 1 or not concurrent_kernels_safe():
        for k in range(len(plan)):
            finished(k, run(k, *(nodes[n] for n in plan[k])))
        return nodes[root], keys[-1]
    waiting, running = list(range(len(plan))), {}
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="surfels-merge") as pool:
        try:
            while waiting or running:
                for k in [k for k in waiting if set(plan[k]) <= nodes.keys()]:
                    running[pool.submit(run, k, *(nodes[n] for n in plan[k]))] = k
                    waiting.remove(k)
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in sorted(done, key=running.get):
                    finished(running.pop(future), future.result())
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return nodes[root], keys[-1]
