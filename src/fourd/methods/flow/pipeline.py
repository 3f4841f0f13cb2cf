"""The ``flow`` pipeline (:func:`run`): frames, grid, labels, IRLS over the saddle system,
the implicit function and its meshes, and the method's diagnostics.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from fourd.animation import MeshSequence
from fourd.cache import (
    Chain,
    StageCache,
    cached,
    option_values,
    pack_list,
    report_resumed,
    stage_key,
    unpack_list,
)
from fourd.errors import InputError
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.normals import estimate_normals, pca_normals
from fourd.geometry.outliers import distance_ratio_inliers
from fourd.methods.flow.fit import deep_inside, fit_gradient, fit_implicit, fit_labels
from fourd.methods.flow.grid import (
    SpaceTimeGrid,
    build_grid,
    carve_by_distance,
    carve_visual_hull,
    data_cells,
    frame_motion,
    inside_seeds,
    substeps_for_motion,
    unsigned_distance,
)
from fourd.methods.flow.irls import (
    IRLSResult,
    history_arrays,
    history_from_arrays,
    run_irls,
)
from fourd.methods.flow.mass_levels import mass_meshes
from fourd.methods.flow.options import FINE_RESOLUTION, OBSERVED_RESOLUTION, Options
from fourd.methods.flow.post import (
    FlowField,
    drop_cavities,
    extract_mesh,
    implicit_function,
    redistanced,
)
from fourd.methods.flow.system import neighbourhood
from fourd.progress import progress
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.flow")


class FlowResult(NamedTuple):
    """Everything :func:`run` computes.

    meshes : MeshSequence, one closed mesh per input frame.
    field : FlowField, the 4D implicit function (a ``Field4D``).
    grid : SpaceTimeGrid of the flow solution.
    x : float64 [S, X, Y, Z], the flow solution (characteristic function).
    mass : float64 [T], total mass at each input frame (input units^3: the cells' values times
        their volume).
    mass_error : float, :func:`mass_conservation_error` of ``mass``.
    history : list of dict, one per IRLS iteration.
    seconds : dict, wall time per stage.
    frame_points : list of T arrays [P, 3] or None, each input frame's points after the
        outlier filter (None: a missing frame).
    frame_normals : list of T arrays [P, 3] or None, their oriented unit normals (None: a
        frame with fewer than 4 points).
    """

    meshes: MeshSequence
    field: FlowField
    grid: SpaceTimeGrid
    x: np.ndarray
    mass: np.ndarray
    mass_error: float
    history: list
    seconds: dict
    frame_points: list
    frame_normals: list


@dataclass(frozen=True)
class FlowDiagnostics:
    """The flow's own figures.

    Attributes
    ----------
    mass_conservation_error : float
        The paper's figure, a fraction (:func:`mass_conservation_error`).
    """

    mass_conservation_error: float


def mass_conservation_error(mass) -> float:
    """The paper's mass conservation error: standard deviation of the total mass over frames
    relative to its mean (section 6: below 2% in 3D).

    Parameters
    ----------
    mass : array [T] of per-frame totals, or [T, ...] per-frame values to be summed.

    Examples
    --------
    >>> round(mass_conservation_error([1.0, 1.02, 0.98]), 4)
    0.0163
    """
    mass = np.asarray(mass, float)
    totals = mass.reshape(len(mass), -1).sum(axis=1)
    mean = float(totals.mean())
    if mean == 0:
        return 0.0
    return float(np.sqrt(totals.var()) / abs(mean))


def check_missing_frames(missing, count: int) -> None:
    """``missing_frames`` are frames of a sequence of ``count`` frames."""
    bad = [i for i in missing if not 0 <= i < count]
    if bad:
        raise InputError(f"missing_frames {sorted(bad)} are outside the sequence's {count} frames")


def _frame_points(seq: PointCloudSequence, options: Options) -> list[np.ndarray | None]:
    missing = set(options.missing_frames)
    check_missing_frames(missing, len(seq))
    kept = []
    for i, frame in enumerate(seq.frames):
        if i in missing:
            kept.append(None)
            continue
        mask = distance_ratio_inliers(frame.points, factor=options.outlier_factor)
        kept.append(frame.points[mask])
    if all(p is None or len(p) < 4 for p in kept):
        raise InputError("no frame has data (all frames missing or nearly empty)")
    return kept


def _outward_weights(grid: SpaceTimeGrid, slice_points, slice_normals, cosine: float) -> np.ndarray:
    """First-iteration continuity weights: 0 on outward boundary faces of data cells, else 1."""
    weights = np.ones((3, *grid.shape4))
    for s, (pts, nrm) in enumerate(zip(slice_points, slice_normals, strict=True)):
        if pts is None:
            continue
        cell = grid.cell_of(pts)
        key = (cell[:, 0] * grid.shape[1] + cell[:, 1]) * grid.shape[2] + cell[:, 2]
        mean = np.zeros((int(np.prod(grid.shape)), 3))
        np.add.at(mean, key, nrm)
        norm = np.linalg.norm(mean, axis=1)
        has = norm > 0
        mean[has] /= norm[has, None]
        mean = mean.reshape(*grid.shape, 3)
        for axis in range(3):
            plus = has.reshape(grid.shape) & (mean[..., axis] > cosine)
            minus = has.reshape(grid.shape) & (-mean[..., axis] > cosine)
            weights[axis, s][plus] = 0.0
            shifted = np.zeros(grid.shape, dtype=bool)
            index = [slice(None)] * 3
            source = [slice(None)] * 3
            index[axis] = slice(0, -1)
            source[axis] = slice(1, None)
            shifted[tuple(index)] = minus[tuple(source)]
            weights[axis, s][shifted] = 0.0
    return weights


#: The cache entries of the flow: the grid, visual hull and initial labels; each IRLS
#: iteration while the solve runs (removed when it ends); the solve's result; the implicit
#: function and the meshes.
LABELS_STAGE = "flow-labels"
STEP_STAGE = "flow-iteration"
IRLS_STAGE = "flow-irls"
POST_STAGE = "flow-post"
#: Options that act only in the IRLS (left out of the labels' cache key).
IRLS_OPTIONS = (
    "neighbourhood", "alpha", "regularization", "regularize_towards", "exponent",
    "weight_floor", "weight_scale", "clamp", "stop_fraction", "max_iterations", "gamma",
    "softness", "outer_rtol", "inner_rtol", "inner", "max_outer", "later_outer",
    "reuse_interpolation", "reuse_coarse", "interpolation_entries", "coarse_drop",
    "parallel_sweeps", "outward_cosine", "still_interior",
)
#: Options that act only after the IRLS (left out of its cache keys).
POST_OPTIONS = (
    "refine", "band", "smoothness", "time_smoothness", "min_component", "cavities",
    "mass_levels", "observed_distance", "level_limit", "unobserved_smoothing",
)


class _Labels(NamedTuple):
    """What the preprocessing gives the IRLS (:func:`_labels`)."""

    frame_points: list  # T arrays [P, 3] or None
    grid: SpaceTimeGrid
    outside: np.ndarray  # bool [S, X, Y, Z], carved by the hull
    value: np.ndarray  # float64 [S, X, Y, Z], initial labels (nan free, 0 outside, 1 inside)
    trim: np.ndarray  # bool [S, X, Y, Z]
    guess: np.ndarray  # bool [S, X, Y, Z], inside the implicit fit
    slice_normals: list  # S arrays [P, 3] or None


def _labels(seq: PointCloudSequence, options: Options, seconds: dict) -> _Labels:
    """Frames, grid, visual hull, the low-resolution implicit fit and the initial labels
    (steps 1 and 2 of the package docstring)."""
    clock = time.perf_counter()
    frame_points = _frame_points(seq, options)
    present = [p for p in frame_points if p is not None and len(p)]
    bounds = np.stack(
        [
            np.min([p.min(axis=0) for p in present], axis=0),
            np.max([p.max(axis=0) for p in present], axis=0),
        ]
    )
    substeps = options.time_substeps
    if substeps == 0:
        h = build_grid(bounds, seq.times, resolution=options.resolution, substeps=1).h
        substeps = substeps_for_motion(
            frame_motion(frame_points), h, limit=options.motion_limit, most=options.max_substeps
        )
        log.info("flow: %d time slices per frame interval (automatic)", substeps)
    grid = build_grid(bounds, seq.times, resolution=options.resolution, substeps=substeps)
    S = grid.slices
    slice_points, slice_sensors = _slice_data(seq, grid, frame_points)

    # (1) preprocessing: hull, data cells, seeds
    outside = np.zeros(grid.shape4, dtype=bool)
    data = np.zeros(grid.shape4, dtype=bool)
    seeds = np.zeros(grid.shape4, dtype=bool)
    trim = np.zeros(grid.shape4, dtype=bool)
    h = grid.h
    for s in progress(range(S), desc="flow: visual hull", total=S):
        pts = slice_points[s]
        if pts is None:
            continue
        spacing = point_spacing(pts)
        if slice_sensors[s] is not None:
            carved = carve_visual_hull(grid, pts, slice_sensors[s], spacing=spacing, margin=1.5 * h)
        else:
            carved = carve_by_distance(grid, pts, distance=3.0 * h)
        cells = data_cells(grid, pts)
        carved &= ~cells
        outside[s] = carved
        if options.hull_trim and slice_sensors[s] is not None:
            trim[s] = ~cells & carve_visual_hull(
                grid, pts, slice_sensors[s], spacing=spacing, margin=1.5 * h, rim=1
            )
        data[s] = cells
        # only the cells inside the hull can be seeds
        distance = unsigned_distance(grid, pts, where=~(carved | cells))
        seeds[s] = inside_seeds(distance, carved | cells, minimum=1.5 * h)
    seconds["hull"] = time.perf_counter() - clock

    # low-resolution 4D implicit fit: improves labels, orients normals
    clock = time.perf_counter()
    fit_normals = None
    fit_offset = options.fit_offset
    if fit_offset is None:
        fit_offset = 1.0 if options.resolution >= FINE_RESOLUTION else 0.0
    if fit_offset > 0:
        fit_normals = [
            None if pts is None else estimate_normals(pts, k=16, sensors=slice_sensors[s]).normals
            for s, pts in enumerate(slice_points)
        ]
    fit = fit_implicit(
        grid, slice_points, outside, seeds & ~data, normals=fit_normals, offset=fit_offset
    )
    fit_inside, fit_outside = fit_labels(fit.values, outside | data, level=options.fit_level)
    depth = options.deep_inside
    if depth is None:
        depth = 2.0 if options.resolution >= FINE_RESOLUTION else 4.0
    if depth > 0:
        fit_inside |= deep_inside(fit.values, outside | data, distance=depth)
    slice_normals: list[np.ndarray | None] = [None] * S
    for s, pts in enumerate(slice_points):
        if pts is None:
            continue
        # the PCA directions (the fit's offset points already have them), signed by the fit
        normals = pca_normals(pts, 16).normals if fit_normals is None else fit_normals[s].copy()
        gradient = fit_gradient(grid, fit.values[s], pts)
        flip = np.einsum("ij,ij->i", normals, gradient) < 0
        normals[flip] *= -1
        slice_normals[s] = normals
    seconds["fit"] = time.perf_counter() - clock

    # initial labels
    value = np.full(grid.shape4, np.nan)
    value[outside | fit_outside] = 0.0
    value[data | seeds | fit_inside] = 1.0
    log.info(
        "flow grid %s x %d slices, cell %.4g; %.1f%% of cells labelled outside, %d data cells, "
        "%d inside seeds",
        grid.shape,
        S,
        h,
        100 * (value == 0).mean(),
        int(data.sum()),
        int((seeds | fit_inside).sum()),
    )
    return _Labels(frame_points, grid, outside, value, trim, fit.values < 0, slice_normals)


def _slice_data(seq: PointCloudSequence, grid: SpaceTimeGrid, frame_points: list):
    """Per time slice, the points (the frame's with at least 4, else None) and sensors."""
    slice_points: list[np.ndarray | None] = [None] * grid.slices
    slice_sensors: list[np.ndarray | None] = [None] * grid.slices
    for i, pts in enumerate(frame_points):
        if pts is not None and len(pts) >= 4:
            slice_points[grid.frame_slice[i]] = pts
            slice_sensors[grid.frame_slice[i]] = seq.frames[i].sensors
    return slice_points, slice_sensors


def _labels_arrays(labels: _Labels) -> dict[str, np.ndarray]:
    grid = labels.grid
    return {
        **pack_list("frame_points", labels.frame_points),
        **pack_list("slice_normals", labels.slice_normals),
        "origin": grid.origin, "h": np.array(grid.h), "shape": np.array(grid.shape),
        "times": grid.times, "frame_slice": grid.frame_slice, "outside": labels.outside,
        "value": labels.value, "trim": labels.trim, "guess": labels.guess,
    }


def _labels_from_arrays(arrays) -> _Labels:
    grid = SpaceTimeGrid(
        arrays["origin"], float(arrays["h"]), tuple(int(n) for n in arrays["shape"]),
        arrays["times"], arrays["frame_slice"],
    )
    return _Labels(
        unpack_list(arrays, "frame_points"), grid, arrays["outside"], arrays["value"],
        arrays["trim"], arrays["guess"], unpack_list(arrays, "slice_normals"),
    )


def _post(options: Options, grid, irls, trim, frame_points, slice_points, slice_normals):
    """Step 5: the implicit function, its meshes at the input times and their masses;
    ``(field, meshes, mass, frames with cavities)``."""
    h = grid.h
    field = implicit_function(
        grid,
        np.where(trim, 0.0, irls.x),
        slice_points,
        slice_normals,
        refine=options.refine,
        band=options.band,
        smoothness=options.smoothness,
        time_weight=options.time_smoothness,
    )
    mass = irls.x[grid.frame_slice].reshape(len(frame_points), -1).sum(axis=1) * h**3
    meshes = [
        extract_mesh(field, int(s), min_component=options.min_component) for s in grid.frame_slice
    ]
    filled = [drop_cavities(*mesh) for mesh in meshes]
    cavity_frames = [i for i, (*_, count) in enumerate(filled) if count]
    if not options.cavities:
        meshes = [(v, f) for v, f, _ in filled]
    if options.mass_levels:
        meshes = level_meshes(meshes, frame_points, mass, h, options)
    return field, meshes, mass, cavity_frames


def level_meshes(meshes, frame_points, mass, h: float, options: Options, volume=None) -> list:
    """:func:`~.mass_levels.mass_meshes` with ``options``' settings: the frames' closed meshes
    with their unobserved parts moved to enclose one volume (``volume``, input units^3; None:
    their mean contoured volume)."""
    return mass_meshes(
        meshes,
        frame_points,
        mass,
        h=h,
        reach=options.observed_distance,
        observed_cell=h * max(1.0, options.resolution / OBSERVED_RESOLUTION),
        limit=options.level_limit,
        smoothing=options.unobserved_smoothing,
        all_or_nothing=options.mass_levels == "auto",
        target=volume,
    )


def run(seq: PointCloudSequence, options: Options | None = None) -> FlowResult:
    """Reconstruct ``seq`` and return every intermediate result (see :class:`FlowResult`).

    With ``options.cache_dir``, the labels (grid, hull, fit), each IRLS iteration, the
    solve's result and the meshes are kept there as they finish, and a rerun resumes after
    the last one (:mod:`fourd.cache`) with the same result.
    """
    options = Options() if options is None else options
    if options.window and len(seq) > options.window:
        raise InputError(
            f"window {options.window}: this run needs one flow solve over all {len(seq)} frames "
            "(fourd.methods.flow.reconstruct and reconstruct_streamed solve in windows; set "
            "window to 0)"
        )
    cache = StageCache(options.cache_dir)
    seconds = {}
    offsets = neighbourhood(options.neighbourhood)
    labels_key = irls_base = irls_key = ""
    if cache.enabled:
        frames = [(frame.points, frame.sensors) for frame in seq.frames]
        labels_key = stage_key(
            LABELS_STAGE, frames, seq.times,
            option_values(options, without=IRLS_OPTIONS + POST_OPTIONS),
        )
        irls_base = stage_key(
            STEP_STAGE, labels_key,
            option_values(options, without=POST_OPTIONS + ("max_iterations", "stop_fraction")),
        )
        irls_key = stage_key(IRLS_STAGE, irls_base, options.max_iterations, options.stop_fraction)

    stored, resumed = cached(
        cache, LABELS_STAGE, labels_key, lambda: _labels_arrays(_labels(seq, options, seconds))
    )
    labels = _labels_from_arrays(stored)
    if resumed:
        report_resumed(log, "the flow's grid, visual hull and initial labels")
    frame_points, grid, trim, slice_normals = (
        labels.frame_points, labels.grid, labels.trim, labels.slice_normals
    )
    slice_points, _ = _slice_data(seq, grid, frame_points)
    value = labels.value

    # (3)+(4) IRLS with the saddle-point solver
    clock = time.perf_counter()

    solved = []  # the result as computed (its history as it is, not read back)

    def solve():
        solved.append(
            _solve(options, value, labels, slice_points, slice_normals, offsets, cache, irls_base)
        )
        return {
            "x": solved[0].x, "decided": solved[0].decided,
            "iterations": np.array(solved[0].iterations), **history_arrays(solved[0].history),
        }

    stored, resumed = cached(cache, IRLS_STAGE, irls_key, solve)
    irls = solved[0] if solved else IRLSResult(
        stored["x"], stored["decided"], int(stored["iterations"]), history_from_arrays(stored)
    )
    if resumed:
        report_resumed(log, "the flow solve")
    elif cache.enabled:
        # the iterations' entries (with the AMG hierarchies) are no longer needed
        _steps(cache, irls_base, options).discard()
    seconds["flow"] = time.perf_counter() - clock

    # (5) postprocessing
    clock = time.perf_counter()
    post_key = stage_key(POST_STAGE, irls_key, option_values(options)) if cache.enabled else ""

    def post():
        field, meshes, mass, cavity_frames = _post(
            options, grid, irls, trim, frame_points, slice_points, slice_normals
        )
        return {
            "values": field.values, "origin": field.origin, "spacing": np.array(field.spacing),
            "times": field.times, "mass": mass,
            "cavity_frames": np.array(cavity_frames, dtype=np.int64),
            **pack_list("vertices", [v for v, _ in meshes]),
            **pack_list("faces", [f for _, f in meshes]),
        }

    stored, resumed = cached(cache, POST_STAGE, post_key, post)
    field = FlowField(stored["values"], stored["origin"], float(stored["spacing"]), stored["times"])
    meshes = list(zip(unpack_list(stored, "vertices"), unpack_list(stored, "faces"), strict=True))
    mass, cavity_frames = stored["mass"], [int(i) for i in stored["cavity_frames"]]
    if resumed:
        report_resumed(log, "the flow's meshes")
    if cavity_frames:
        log.warning(
            "flow: closed cavities inside the solid in %d of %d frames (%s): the motion is "
            "faster than the flow's speed bound of one cell per time slice, and conserving mass "
            "pulled material out of the interior. Raise time_substeps (0: automatic).%s",
            len(cavity_frames),
            len(meshes),
            ", ".join(map(str, cavity_frames))[:80],
            "" if options.cavities else " The cavities were filled.",
        )
    result_meshes = MeshSequence(tuple(meshes), seq.times)
    seconds["post"] = time.perf_counter() - clock

    error = mass_conservation_error(mass)
    log.info(
        "flow: mass conservation error %.2f%% over %d frames (%d IRLS iterations); %s",
        100 * error,
        len(seq),
        irls.iterations,
        ", ".join(f"{k} {v:.1f}s" for k, v in seconds.items()),
    )
    frame_normals = [
        None if p is None or len(p) < 4 else slice_normals[grid.frame_slice[i]]
        for i, p in enumerate(frame_points)
    ]
    return FlowResult(
        result_meshes, field, grid, irls.x, mass, error, irls.history, seconds, frame_points,
        frame_normals,
    )


def _steps(cache: StageCache, base: str, options: Options) -> Chain:
    """The cache entries of the IRLS iterations."""
    return Chain.of(cache, STEP_STAGE, base, [()] * options.max_iterations)


def _solve(options, value, labels, slice_points, slice_normals, offsets, cache, base):
    """Steps 3 and 4: the IRLS over the saddle-point systems from the initial labels."""
    grid = labels.grid
    solver_options = {
        "gamma": options.gamma,
        "softness": options.softness,
        "rtol": options.outer_rtol,
        "inner": options.inner,
        "inner_rtol": options.inner_rtol,
        "maxiter": options.max_outer,
        "interpolation_entries": options.interpolation_entries or None,
        "coarse_drop": options.coarse_drop,
    }
    still_depth = options.still_interior
    if still_depth is None:
        still_depth = 1 if options.resolution >= FINE_RESOLUTION else 0
    bar = progress(total=options.max_iterations, desc="flow: IRLS", unit="iteration")
    try:
        return run_irls(
            value,
            # the IRLS writes its later weights into this array
            _outward_weights(grid, slice_points, slice_normals, options.outward_cosine),
            offsets,
            ~labels.outside,
            alpha=options.alpha,
            reg=options.regularization,
            exponent=options.exponent,
            floor=options.weight_floor,
            scale=options.weight_scale,
            clamp=options.clamp,
            stop_fraction=options.stop_fraction,
            max_iterations=options.max_iterations,
            solver_options=solver_options,
            guess=labels.guess.astype(float),
            regularize_towards=options.regularize_towards,
            reuse_interpolation=options.reuse_interpolation,
            reuse_coarse=options.reuse_coarse,
            later_maxiter=options.later_outer or None,
            parallel=options.parallel_sweeps and options.inner == "amg",
            still_depth=still_depth,
            progress=bar,
            checkpoints=_steps(cache, base, options) if cache.enabled else None,
        )
    finally:
        bar.close()


def surface_distance(result: FlowResult) -> FlowField:
    """A signed distance to ``result``'s closed meshes at the input times, on the flow's grid
    (:func:`~.post.redistanced`): a :class:`~fourd.geometry.field.Field4D` to slide a
    template along."""
    return redistanced(result.field, result.grid.frame_slice, result.meshes.meshes)
