"""Method ``kinematic``: a 4D implicit surface (4D MPU over a hextree), the urshape extracted
at the first time, and the urshape slid along the space-time surface as rigidly as possible.

Pipeline (000_00387fefe94cc850.txt):

1. space-time point cloud (section 2): per-frame outlier removal (beyond the paper: points
   whose mean distance to their neighbours is far above the typical one), per-frame normals
   (given, or PCA oriented by the sensors or by propagation), 4D points ``(x, y, z, w)`` with
   ``w = delta * (t - t0) / dt`` (``dt`` the median frame step) and 4D normals ``(n, 0)``;
   ``delta`` is the median nearest-neighbour spacing of the first frame (the paper takes the
   median edge length of a triangulation of the first frame, which estimates the same
   sampling distance), times ``time_scale`` (default 2; the paper uses 1, see Options);
2. 4D MPU (section 3, :mod:`.mpu4d`), over all frames or over sliding windows of frames;
3. urshape (section 4, :mod:`.urshape`);
4. sliding (section 5, :mod:`.sliding`), optionally with sub-steps in time;
5. output at the input times or at any requested ``times``.

Beyond the paper (all documented options): robust MPU error / normal-spread quantile,
rigid point-to-plane prediction of the initial guess, constraint linearised at the guess,
time sub-steps, sliding windows of frames for the 4D fit, every second point in the 4D fit
(``fit_stride``), ``time_scale`` 2, the data term and temporal smoothing.

Known limit of the paper's sliding: motion between frames much larger than the features
(crane's kicking leg, up to 14% of the diagonal per kept frame) leaves no space-time surface
connecting the frames, and the projection of 5.1 loses that limb. With ``large_motion``
(default) such frames are first registered to their own points by as-rigid-as-possible ICP
(:mod:`.register`); crane correspondence 0.027 / 0.046 -> 0.011 / 0.015 (mean / last frame).

Measured limit of the implicit itself, and the data term that removes it (rigid-turn, standard
scans): registering the *true* shape rigidly to ``f(., t) = 0`` frame by frame leaves pose
errors of 0.005-0.013 of the diagonal (about 2 degrees at the first frame, 3 at the last, near
0 in the middle: the fit blends neighbouring frames and is one-sided at the ends), while
point-to-plane ICP of the same shape to the raw points of each frame is at 0.001. Giving the
4D normals a time component did not change this, nor did an ICP guess against the raw points
while constraint (2) tied the vertices back to ``f``. So with ``data_term`` (default) the
urshape is projected onto the first frame's own points and, at every input time, the observed
vertices are registered (one rigid motion, iterated), projected and constrained against that
frame's IMLS surface (:mod:`.framesurface`), the 4D implicit filling in where the frame has no
points. Measured: rigid-turn correspondence 0.029 / 0.058 (mean / last frame) -> 0.0017 /
0.0026; the price is each frame's own scan noise, taken out by one temporal smoothing pass.
Local rigid patches are not used against the data: on the turning blob they let the surface
slide (0.026 with 800-vertex patches against 0.002 without).

Public functions reused by other methods: :func:`extract_template` and :func:`slide`
(both take any :class:`fourd.geometry.field.Field4D`).
"""

from __future__ import annotations

import logging
import time as _time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp

from fourd.animation import AnimatedMesh
from fourd.errors import InputError
from fourd.geometry.neighbors import knn, neighbours_among, point_spacing
from fourd.geometry.normals import estimate_normals
from fourd.geometry.outliers import distance_ratio_inliers
from fourd.methods.kinematic.field import SpaceTimeField, fit_windows, space_time_points
from fourd.methods.kinematic.framesurface import FrameSurface
from fourd.methods.kinematic.mpu4d import MPU4D, MPUOptions, fit_mpu4d
from fourd.methods.kinematic.register import RegisterOptions
from fourd.methods.kinematic.sliding import (
    SlideOptions,
    arap_energy,
    median_edge_length,
    project_to_surface,
    slide,
    slide_precompute,
)
from fourd.methods.kinematic.urshape import extract_template
from fourd.sequence import PointCloudSequence

__all__ = [
    "MIN_FRAMES",
    "Options",
    "reconstruct",
    "animate",
    "extract_template",
    "slide",
    "SlideOptions",
    "project_to_surface",
    "arap_energy",
    "slide_precompute",
    "fit_mpu4d",
    "MPUOptions",
    "MPU4D",
    "SpaceTimeField",
    "space_time_points",
    "prepare_frames",
    "template_cell_size",
    "FrameSurface",
    "smooth_trajectories",
]

log = logging.getLogger("fourd.methods.kinematic")

#: A space-time fit needs at least two frames.
MIN_FRAMES = 2
#: Neighbours of the per-frame outlier test (mean distance to them).
OUTLIER_NEIGHBOURS = 8
#: After a kept large-motion registration, the projection of 5.1 may move a vertex at most
#: this many median edges (:class:`SlideOptions` ``projection_limit``).
PROJECTION_LIMIT = 1.5
#: With ``animate(project_smoothed=True)``: only the vertices that the trajectory smoothing
#: moved farther than this many median edges are projected back onto the surface.
SMOOTHED_PROJECTION_MIN = 1.0
#: Neighbourhood (vertices, itself included) over which :func:`smooth_trajectories` averages a
#: deviation from the neighbouring frames before it tells motion from noise.
SMOOTHING_NEIGHBOURS = 48
#: Threads of :func:`prepare_frames` (frames prepared at once).
PREPARE_THREADS = 2


@dataclass(frozen=True)
class Options:
    """Options of the ``kinematic`` method. Lengths are in input units; 0 means "derive from
    the data" (``s`` below is the median nearest-neighbour spacing of the first frame).

    Attributes
    ----------
    mpu_error : float
        MPU error epsilon_0 (Taubin distance of a leaf's function to its points, see
        ``error_quantile``); 0: ``2 * s``.
    error_quantile : float
        Robust quantile of the MPU error and normal-spread tests (1.0: the paper's maximum).
    min_points : int
        N_min of the MPU fit (points per leaf support at least).
    time_scale : float
        Multiplies ``delta`` (the 4D distance between consecutive frames, ``s``). The paper's
        choice is 1; the default 2 spreads the frames further apart in 4D so that a leaf's
        support spans fewer frames and ``f(., t)`` lags less behind fast motion (measured with
        the standard scans: correspondence on dfaust-hopping 0.0046 -> 0.0042, rigid-turn
        0.079 -> 0.030, crane Chamfer 0.0101 -> 0.0077; 4 helps rigid-turn and crane further
        but doubles the jitter on dfaust-hopping).
    cell_size : float
        Urshape marching-cubes cell size; 0: chosen from the first frame's surface area so
        that the urshape has about ``template_vertices`` vertices.
    template_vertices : int
        Target size of the urshape when ``cell_size`` is 0.
    smoothing_iterations : int
        Laplacian smoothing steps of the urshape before its projection onto ``f = 0``.
    iterations : int
        Fixed sliding iterations per time step (the paper: 3-10).
    substeps : int
        Sliding sub-steps between consecutive output times (1: the paper).
    epsilon : float
        Radius of the data ball of section 5.4; 0: ``2 *`` the urshape's median edge, at least
        ``3 * s``.
    rigid_guess : bool
        Rigid (point-to-plane on the implicit) prediction before the projection of 5.1
        (beyond the paper; see :class:`SlideOptions`).
    rigid_neighbours : int
        Patch size of the local rigid predictions (0: one global rigid motion only).
    window : int
        Frames per 4D fit (0: one fit over the whole sequence); longer sequences are fitted
        window by window with ``window_overlap`` extra frames on each side.
    window_overlap : int
        Extra frames on both sides of each window that its 4D fit takes in (with ``window``),
        so that ``f`` is continuous enough across the windows' boundaries.
    outlier_factor : float
        Per-frame outlier removal: drop points whose mean distance to their 8 nearest
        neighbours exceeds this multiple of the median of that distance (0: keep all).
    normals_k : int
        Neighbours for PCA normals when the input has none.
    fit_stride : int
        Every ``fit_stride``-th cleaned point of each frame enters the 4D fit (1: all). The
        data term, the spacing and the observed flags still use every point. Measured with
        ``exp`` runs of the standard scans (20k samples; Chamfer / completeness-95 /
        correspondence mean), all points against every second one: dfaust-hopping
        0.0036 / 0.0176 / 0.0045 and 0.0036 / 0.0176 / 0.0044, rigid-turn 0.0062 / 0.0515 /
        0.0017 and 0.0062 / 0.0514 / 0.0016, crane 0.0087 / 0.068 / 0.028 and 0.0069 /
        0.045 / 0.025; the fit takes about half the time. Every third or fourth point was
        no faster overall and noisier on crane.
    data_term : bool
        At output times that are input times, register, project and constrain the observed
        vertices against that frame's own points (an IMLS surface,
        :mod:`.framesurface`) instead of the 4D implicit, whose zero set lags a little behind
        or ahead of each frame; the 4D implicit still fills holes, links the frames and gives
        the urshape (beyond the paper; ``fourd bench`` with the standard scans, correspondence
        mean / last frame: rigid-turn 0.029 / 0.058 -> 0.0015 / 0.0024, crane 0.031 / 0.059
        -> 0.030 / 0.053, dfaust-hopping 0.0041 / 0.0057 -> 0.0043 / 0.0055).
    data_bandwidth : float
        Gaussian width of that surface; 0: ``2 * s``.
    large_motion : bool
        With the data term: at an input time where the predicted template leaves more than
        3% of the frame's points farther than ``1.5 epsilon`` from it (a limb moved farther
        than its width), register the template to those points by as-rigid-as-possible ICP
        before the projection, and keep the result when it explains more of them
        (:mod:`.register`; beyond the paper). After a kept registration, the projection of
        5.1 may move a vertex at most 1.5 median edges; one that would move farther is left
        unconstrained for that step (``SlideOptions.projection_limit``).
    shape_memory : float
        Weight of the previous frame's shape in the large-motion registration's
        as-rigid-as-possible term (``RegisterOptions.previous_shape``; 0: the template's rest
        shape alone). 0.5 suits captured people and animals, whose skin stretches and twists,
        not rigid parts, twisting tubes or shapes that split, so it is off by default (the
        figures are with ``RegisterOptions.previous_shape``).
    slide_memory : float
        Weight of the previous frame's shape in the sliding's as-rigid-as-possible term
        (``SlideOptions.previous_shape``; 0: the urshape alone, the paper). Off by default:
        it helps the held-out crane stretches and the shapes that stretch, not crane itself.
        ``exp`` runs at 0.8 (20k samples, correspondence mean / last frame, 0 -> 0.8): crane
        0.0073 / 0.0120 -> 0.0074 / 0.0134, crane-50 0.0235 / 0.0308 -> 0.0207 / 0.0299,
        crane-90 0.0095 / 0.0150 -> 0.0090 / 0.0130, crane-130 0.0114 / 0.0177 -> 0.0108 /
        0.0172, crane-still 0.0016 / 0.0027 -> 0.0013 / 0.0016, bending-arm 0.0202 / 0.0338
        -> 0.0203 / 0.0271, touching-spheres 0.0158 / 0.0243 -> 0.0128 / 0.0205 (jitter 3.10
        -> 1.35), waving-sheet 0.0313 / 0.0425 -> 0.0286 / 0.0328, splitting-blob Chamfer /
        completeness-95 0.0164 / 0.0152 -> 0.0099 / 0.0085; but rigid-turn 0.0012 / 0.0017 ->
        0.0014 / 0.0023, dfaust-hopping 0.0043 / 0.0061 -> 0.0044 / 0.0066, squash-ball
        0.0226 / 0.0066 -> 0.0229 / 0.0106, horse-gallop 0.0087 / 0.0043 -> 0.0093 / 0.0055.
        With ``shape_memory`` 0.5 as well (for captured people): crane 0.0070 / 0.0117,
        crane-50 0.0144 / 0.0195, crane-90 0.0090 / 0.0113, crane-130 0.0113 / 0.0173, but
        bending-arm 0.0243 / 0.0431, squash-ball 0.0277 / 0.0312, elephant-gallop 0.0277 /
        0.0356.
    still_normals : float
        With the data term: where the 4D implicit moves less than this many median edges per
        step, constraint (2) takes its normal from the implicit, which is smooth over time,
        instead of from the frame's noisy surface, so a still part does not creep along
        itself (``SlideOptions.still_normals``; 0: never). A still crane, 20 frames: last-frame
        correspondence 0.0095 -> 0.0026.
    temporal_smoothing : int
        Passes of a ``[1/4, 1/2, 1/4]`` filter over the vertex trajectories (time-weighted for
        uneven output times; the first and last frames stay): the data term gives every frame
        its own scan noise (jitter on dfaust-hopping 2.2 without, 0.82 with one pass).
    smoothing_motion : float
        The filter keeps out of the shape's accelerations: its step shrinks where a vertex's
        neighbourhood deviates from the neighbouring frames together, and keeps doing so in
        the next frames, by more than this multiple of the median deviation
        (:func:`smooth_trajectories`; 0: the plain filter everywhere). The plain filter cut
        crane's kicking leg off the surface (per-frame accuracy 0.0022 unsmoothed against
        0.0029 smoothed at the kick's peak). ``fourd bench``, Chamfer / jitter, plain and with
        this at 1: crane 0.0027 / 0.79 and 0.0024 / 0.96, dfaust-hopping 0.0025 / 0.75 and
        0.0025 / 0.78, crane-90 and crane-130 0.0028 -> 0.0025, the others within 0.0002.
        Without the condition in time (only the shared deviation, at 3), a one-frame jump of a
        whole region counted as motion: touching-spheres jitter 2.96 -> 8.1, squash-ball's
        bounce 0.95 -> 1.60.
    times : tuple of float
        Output times (default: the input times). They may lie between or beyond input times.
    seed : int
        Seed for the subsampling of the spacing estimate.
    """

    mpu_error: float = 0.0
    error_quantile: float = 0.95
    min_points: int = 40
    time_scale: float = 2.0
    cell_size: float = 0.0
    template_vertices: int = 10000
    smoothing_iterations: int = 5
    iterations: int = 4
    substeps: int = 1
    epsilon: float = 0.0
    rigid_guess: bool = True
    rigid_neighbours: int = 48
    window: int = 0
    window_overlap: int = 2
    outlier_factor: float = 3.0
    normals_k: int = 16
    fit_stride: int = 2
    data_term: bool = True
    data_bandwidth: float = 0.0
    large_motion: bool = True
    shape_memory: float = 0.0
    slide_memory: float = 0.0
    still_normals: float = 0.2
    temporal_smoothing: int = 1
    smoothing_motion: float = 1.0
    times: tuple[float, ...] = ()
    seed: int = 0

    def __post_init__(self):
        for name in (
            "mpu_error", "cell_size", "epsilon", "outlier_factor", "data_bandwidth",
            "still_normals", "smoothing_motion",
        ):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must not be negative")
        if self.time_scale <= 0:
            raise ValueError("time_scale must be positive")
        if self.iterations < 1 or self.substeps < 1:
            raise ValueError("iterations and substeps must be at least 1")
        if self.min_points < 15:
            raise ValueError("min_points must be at least 15")
        if not (0.5 <= self.error_quantile <= 1.0):
            raise ValueError("error_quantile must lie in [0.5, 1]")
        if self.template_vertices < 100:
            raise ValueError("template_vertices must be at least 100")
        if self.fit_stride < 1:
            raise ValueError(f"fit_stride must be at least 1, got {self.fit_stride}")
        if self.window < 0 or self.window_overlap < 0:
            raise ValueError("window and window_overlap must not be negative")
        if not 0.0 <= self.shape_memory < 1.0:
            raise ValueError(f"shape_memory must lie in [0, 1), got {self.shape_memory}")
        if not 0.0 <= self.slide_memory < 1.0:
            raise ValueError(f"slide_memory must lie in [0, 1), got {self.slide_memory}")
        if self.temporal_smoothing < 0:
            raise ValueError("temporal_smoothing must not be negative")
        object.__setattr__(self, "times", tuple(float(t) for t in self.times))


def template_cell_size(points: np.ndarray, spacing: float, vertices: int) -> float:
    """Marching-cubes cell size giving about ``vertices`` urshape vertices.

    The surface area is estimated from the voxels of size ``2 * spacing`` that hold points
    (a surface crosses about 1.5 / c^2 voxels of size c per unit area, averaged over
    orientations), and marching cubes makes about 1.5 vertices per ``cell^2`` of area.
    """
    voxel = 2.0 * spacing
    keys = np.unique(np.floor(points / voxel).astype(np.int64), axis=0)
    area = len(keys) * voxel**2 / 1.5
    return float(np.sqrt(1.5 * area / vertices))


def prepare_frames(seq: PointCloudSequence, options: Options):
    """Per-frame cleaning and normals: returns ``(points, normals)`` lists (pure per frame).

    Frames are prepared two at a time on two threads (their compiled kernels release the GIL)
    when numba's threading layer allows concurrent parallel kernels; the result is the same
    as one after the other."""
    frames = list(seq.frames)
    if not frames:
        return [], []
    first = _prepare_frame(frames[0], options)
    if len(frames) == 1 or not _concurrent_kernels_safe():
        rest = [_prepare_frame(frame, options) for frame in frames[1:]]
    else:
        with ThreadPoolExecutor(max_workers=PREPARE_THREADS) as pool:
            rest = list(pool.map(lambda frame: _prepare_frame(frame, options), frames[1:]))
    prepared = [first] + rest
    return [p for p, _ in prepared], [n for _, n in prepared]


def _concurrent_kernels_safe() -> bool:
    """Whether numba's threading layer (chosen at the first parallel kernel) lets two threads
    run parallel kernels at once: ``tbb`` and ``omp`` do, ``workqueue`` aborts the process."""
    try:
        return numba.threading_layer() in ("tbb", "omp")
    except ValueError:  # no parallel kernel has run yet
        return False


def _prepare_frame(frame, options: Options):
    """One frame's kept points [P', 3] and their oriented normals [P', 3]."""
    # one neighbour query per frame serves the outlier test (8 neighbours) and the normals
    # of the kept points (a margin of 4 for the dropped ones; rows that keep fewer are
    # queried again)
    distances = indices = None
    if frame.normals is None:
        k = max(OUTLIER_NEIGHBOURS, options.normals_k) + 4
        distances, indices = knn(frame.points, min(k, len(frame.points) - 1))
    elif options.outlier_factor > 0 and len(frame.points) > OUTLIER_NEIGHBOURS + 1:
        distances, _ = knn(frame.points, OUTLIER_NEIGHBOURS)
    keep = distance_ratio_inliers(
        frame.points,
        k=OUTLIER_NEIGHBOURS,
        factor=options.outlier_factor,
        statistic="mean",
        distances=distances,
    )
    p = frame.points[keep]
    if frame.normals is not None:
        return p, frame.normals[keep]
    neighbours = neighbours_among(frame.points, indices, keep, options.normals_k)
    n = estimate_normals(p, k=options.normals_k, sensors=frame.sensors, indices=neighbours).normals
    return p, n


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> AnimatedMesh:
    """Animated mesh from a point-cloud sequence by 4D MPU + urshape + ARAP sliding.

    Returns an :class:`AnimatedMesh` with ``rest`` the urshape; one frame per output time
    (default: per input frame). Raises :class:`InputError` when the sequence is too short or
    the implicit has no surface at the first time.

    References
    ----------
    Süßmuth, Winter, Greiner: Reconstructing animated meshes from time-varying point clouds,
    SGP 2008 (000_00387fefe94cc850.txt).
    """
    options = options or Options()
    if len(seq) < MIN_FRAMES:
        raise InputError(f"kinematic needs at least {MIN_FRAMES} frames, got {len(seq)}")
    started = _time.perf_counter()
    times = seq.times
    points, normals = prepare_frames(seq, options)
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
    mpu_options = MPUOptions(
        error=options.mpu_error or 2.0 * spacing,
        min_points=options.min_points,
        error_quantile=options.error_quantile,
    )
    field = fit_windows(
        stp,
        times,
        mpu_options=mpu_options,
        window=options.window,
        overlap=options.window_overlap,
        time_origin=times[0],
        time_scale=time_scale,
    )
    fitted = _time.perf_counter()
    log.info("4D fit: %.2f s", fitted - started)

    result = animate(field, points, normals, times, spacing=spacing, options=options)
    finished = _time.perf_counter()
    log.info(
        "kinematic: %d frames in %.2f s (fit %.2f, urshape and sliding %.2f)",
        len(result.times),
        finished - started,
        fitted - started,
        finished - fitted,
    )
    return result


def animate(
    field,
    points: list[np.ndarray],
    normals: list[np.ndarray],
    times: np.ndarray,
    *,
    spacing: float,
    options: Options,
    closed: bool = False,
    bounds: np.ndarray | None = None,
    project_smoothed: bool = False,
) -> AnimatedMesh:
    """Urshape at ``times[0]`` and its sliding along ``field`` (sections 4 and 5 with this
    method's data term): everything of :func:`reconstruct` after the 4D fit, for any
    :class:`~fourd.Field4D` (the ``flow`` method's ``coherent`` option composes with it).

    Parameters
    ----------
    field : Field4D
        Space-time implicit, negative inside, time in the units of ``times``.
    points, normals : lists of T arrays [P_k, 3]
        Cleaned input points per frame with oriented unit normals (``P_k`` may be 0: a frame
        with no data slides without a data term; frame 0 must have points).
    times : array [T]
        Input times, strictly increasing.
    spacing : float
        Point spacing ``s`` (see :class:`Options`).
    closed : bool
        Polygonise the urshape everywhere in ``bounds`` (a closed template of a closed
        field), not only near the first frame's points (open scans stay open).
    bounds : ndarray [2, 3], optional
        Box of the urshape (default: the first frame's points).
    project_smoothed : bool
        After the trajectory smoothing, project the vertices it moved farther than
        :data:`SMOOTHED_PROJECTION_MIN` median edges back onto the surface (4 Newton steps,
        at most 2 edges each; the template's frame stays): on fast curved motion the filter
        cuts the corners of the trajectories, off the surface. The surface is the frame's own
        points where the data term has them, else ``field``. The vertices the smoothing
        moved less keep their smoothed place: projecting every vertex brought the frames'
        noise back (``flow`` ``coherent=true`` on ``dfaust-hopping``, 20k samples: jitter
        0.89 unprojected, 1.74 all projected, 0.94 with this rule; crane Chamfer /
        completeness-95 0.0034 / 0.0073, 0.0031 / 0.0060 and 0.0032 / 0.0062).
    """
    started = _time.perf_counter()
    times = np.asarray(times, dtype=float)
    cell = options.cell_size or template_cell_size(points[0], spacing, options.template_vertices)
    box = np.array([points[0].min(axis=0), points[0].max(axis=0)]) if bounds is None else bounds

    # the area estimate of template_cell_size is rough on curved or thin shapes
    # (dfaust-hopping: 1.7x the target), so an automatic cell size is corrected once from the
    # marching-cubes vertex count: sliding costs grow with the vertex count
    vertices, faces = extract_template(
        field,
        times[0],
        bounds=np.asarray(box, dtype=float),
        cell_size=cell,
        data_points=None if closed else points[0],
        smoothing_iterations=options.smoothing_iterations,
        min_component_faces=20,
        target_vertices=0 if options.cell_size else options.template_vertices,
    )
    if len(faces) == 0:
        raise InputError("the 4D implicit has no surface at the first frame (too few points?)")
    bandwidth = options.data_bandwidth or 2.0 * spacing
    if options.data_term:
        # the urshape on the first frame's own points: f(., t0) is posed a little off them
        vertices = project_to_surface(
            field,
            vertices,
            times[0],
            surface=FrameSurface(points[0], normals[0], bandwidth),
            max_step=2.0 * median_edge_length(vertices, faces),
        )
    urshape = _time.perf_counter()
    log.info("urshape: %d vertices in %.2f s", len(vertices), urshape - started)

    time_unit = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    out_times = np.array(options.times, dtype=float) if options.times else times.copy()
    out_times = np.unique(out_times)
    nearest = np.abs(out_times[:, None] - times[None, :]).argmin(axis=1)
    data = [points[k] for k in nearest]
    # per output time, the input frame whose surface is the data term there (-1: none)
    exact = np.abs(out_times - times[nearest]) <= 1e-9 * time_unit
    has_points = np.array([len(points[k]) > 0 for k in nearest])
    surface_frames = list(np.where(exact & has_points & options.data_term, nearest, -1))

    def surfaces(frames):
        return _FrameSurfaces(frames, points, normals, bandwidth)

    slide_options = SlideOptions(
        iterations=options.iterations,
        # a vertex is observed when an input point lies within 2 edges, or within 3 point
        # spacings when the urshape is finer than the data
        epsilon=options.epsilon or max(2.0 * median_edge_length(vertices, faces), 3.0 * spacing),
        substeps=options.substeps,
        rigid_guess=options.rigid_guess,
        rigid_neighbours=options.rigid_neighbours,
        # both act only at input times with the data term
        register=(
            RegisterOptions(previous_shape=options.shape_memory) if options.large_motion
            else None
        ),
        projection_limit=PROJECTION_LIMIT,
        still_normals=options.still_normals,
        previous_shape=options.slide_memory,
    )
    t0 = float(times[0])
    forward = out_times >= t0
    parts_v, parts_o = [], []
    if (~forward).any():
        back_times = np.r_[t0, out_times[~forward][::-1]]
        count = int((~forward).sum())
        back = _slide_monotone(
            vertices,
            faces,
            field,
            back_times,
            slide_options,
            [points[0]] + data[:count][::-1],
            surfaces([-1] + surface_frames[:count][::-1]),
        )
        parts_v.append(back[0][1:][::-1])
        parts_o.append(back[1][1:][::-1])
    fwd_times = out_times[forward]
    fwd_data = [data[i] for i in np.flatnonzero(forward)]
    fwd_surfaces = [surface_frames[i] for i in np.flatnonzero(forward)]
    prepend = len(fwd_times) == 0 or fwd_times[0] > t0
    if prepend:
        fwd_times = np.r_[t0, fwd_times]
        fwd_data = [points[0]] + fwd_data
        fwd_surfaces = [-1] + fwd_surfaces
    fv, fo = _slide_monotone(
        vertices, faces, field, fwd_times, slide_options, fwd_data, surfaces(fwd_surfaces)
    )
    if prepend:
        fv, fo = fv[1:], fo[1:]
    parts_v.append(fv)
    parts_o.append(fo)
    slid = np.concatenate(parts_v)
    smoothed = smooth_trajectories(
        slid, out_times, options.temporal_smoothing, motion_threshold=options.smoothing_motion
    )
    if project_smoothed:
        edge = median_edge_length(vertices, faces)
        for k in np.flatnonzero(out_times != t0):
            moved = np.linalg.norm(smoothed[k] - slid[k], axis=1) > SMOOTHED_PROJECTION_MIN * edge
            frame = surface_frames[k]
            smoothed[k][moved] = project_to_surface(
                field,
                smoothed[k][moved],
                float(out_times[k]),
                iterations=4,
                max_step=2.0 * edge,
                surface=FrameSurface(points[frame], normals[frame], bandwidth) if frame >= 0 else None,
            )
    return AnimatedMesh(
        faces=faces,
        vertices=smoothed,
        times=out_times,
        observed=np.concatenate(parts_o),
        rest=vertices,
    )


def smooth_trajectories(
    vertices: np.ndarray,
    times: np.ndarray,
    passes: int,
    *,
    motion_threshold: float = 0.0,
    neighbours: int = SMOOTHING_NEIGHBOURS,
) -> np.ndarray:
    """``passes`` of ``x_k <- x_k + w (x_k^lin - x_k)`` over frames ``vertices`` [T, N, 3], with
    ``x_k^lin`` the linear interpolation of the neighbouring frames at ``times[k]`` (with
    ``w = 1/2`` the ``[1/4, 1/2, 1/4]`` filter for even times); the first and last frames are
    kept.

    ``motion_threshold`` 0: ``w = 1/2`` everywhere. Above 0 the filter keeps out of the
    shape's accelerations: ``w = 1/2 / (1 + (m / (c s))^2)`` with ``c = motion_threshold``,
    ``s`` the median of ``|x^lin - x|`` over all vertices and frames, and ``m`` the part of the
    deviation ``x^lin - x`` that is shared in space and in time: its mean ``a_k`` over the
    vertex's ``neighbours`` nearest vertices in the first frame, taken along itself by the mean
    of ``a_(k-1)`` and ``a_(k+1)``, ``m = min(|a_k|, max(0, a_k . mean / |a_k|))``. One
    vertex's own deviation is the frame's noise, and a whole region's deviation that reverses
    in the next frame is a one-frame jump (a tracking glitch or a bounce): both are smoothed.
    A deviation that a region keeps over consecutive frames is an acceleration (a kick), which
    the plain filter would cut off the surface.
    """
    x = np.array(vertices, dtype=np.float64, copy=True)
    if passes <= 0 or len(x) < 3:
        return x
    t = np.asarray(times, dtype=np.float64)
    a = ((t[2:] - t[1:-1]) / (t[2:] - t[:-2]))[:, None, None]  # weight of the previous frame
    average = None
    if motion_threshold > 0:
        n = x.shape[1]
        k = max(min(neighbours, n), 1)
        near = np.arange(n)[:, None]  # the vertex itself and its k - 1 nearest
        if k > 1:
            near = np.hstack([near, knn(x[0], k - 1)[1]])
        rows = np.repeat(np.arange(n), k)
        average = sp.csr_matrix(
            (np.full(rows.size, 1.0 / k), (rows, near.ravel())), shape=(n, n)
        )
    for _ in range(passes):
        deviation = a * x[:-2] + (1.0 - a) * x[2:] - x[1:-1]
        weight = 0.5
        if average is not None:
            weight = 0.5 / (1.0 + (_shared_motion(deviation, average) / motion_threshold) ** 2)
        x[1:-1] += weight * deviation
    return x


def _shared_motion(deviation: np.ndarray, average: sp.csr_matrix) -> np.ndarray:
    """``m / s`` of :func:`smooth_trajectories`, [T-2, N, 1], from the deviations [T-2, N, 3]
    and the neighbourhood averaging matrix [N, N]."""
    shared = np.stack([average @ d for d in deviation])
    size = np.maximum(np.linalg.norm(shared, axis=2), 1e-300)
    around = np.zeros_like(shared)
    count = np.zeros(len(shared))
    around[1:] += shared[:-1]
    around[:-1] += shared[1:]
    count[1:] += 1.0
    count[:-1] += 1.0
    around /= np.maximum(count, 1.0)[:, None, None]
    kept = np.maximum(np.einsum("kij,kij->ki", shared, around) / size, 0.0)
    scale = max(float(np.median(np.linalg.norm(deviation, axis=2))), 1e-300)
    return (np.minimum(size, kept) / scale)[..., None]


class _FrameSurfaces(Sequence):
    """Per sliding time, the :class:`FrameSurface` of input frame ``frames[i]`` (None where
    it is -1), built when the sliding asks for it: one frame's grid in memory at a time."""

    def __init__(self, frames, points, normals, bandwidth):
        self.frames, self.points, self.normals, self.bandwidth = frames, points, normals, bandwidth

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, i):
        k = int(self.frames[i])
        return None if k < 0 else FrameSurface(self.points[k], self.normals[k], self.bandwidth)


def _slide_monotone(vertices, faces, field, times, options, data, surfaces):
    """Slide through monotone ``times`` (decreasing allowed); returns (frames, observed)."""
    if len(times) == 1:
        from scipy.spatial import cKDTree

        d, _ = cKDTree(data[0]).query(vertices, distance_upper_bound=options.epsilon or np.inf)
        return vertices[None].copy(), np.isfinite(d)[None]
    sign = 1.0 if times[-1] >= times[0] else -1.0
    # slide() wants increasing times: run it on a reflected time axis when going backwards
    if sign > 0:
        anim = slide(vertices, faces, field, times, options=options, data=data, surfaces=surfaces)
    else:
        anim = slide(
            vertices,
            faces,
            _Reflected(field),
            -np.asarray(times),
            options=options,
            data=data,
            surfaces=surfaces,
        )
    return anim.vertices, anim.observed


class _Reflected:
    """``g(x, t) = f(x, -t)``: sliding backwards in time as forwards."""

    def __init__(self, field):
        self.field = field

    def value(self, points, times):
        return self.field.value(points, -np.asarray(times))

    def value_and_gradient(self, points, times):
        return self.value(points, times), self.gradient(points, times)

    def gradient(self, points, times):
        g = self.field.gradient(points, -np.asarray(times)).copy()
        g[:, 3] *= -1.0
        return g
