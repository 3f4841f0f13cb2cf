"""Options of the ``kinematic`` method and its fixed constants."""

from __future__ import annotations

from dataclasses import dataclass

from fourd.animation import AnimatedMesh

#: A space-time fit needs at least two frames.
MIN_FRAMES = 2
#: One connectivity: the urshape slid through every frame.
RESULT = AnimatedMesh
#: The options users change first (``fourd options kinematic``; the others under ``--all``).
COMMON_OPTIONS = (
    "template_vertices",
    "large_motion",
    "shape_memory",
    "slide_memory",
    "window",
    "temporal_smoothing",
    "times",
)
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
#: With ``densify``: samples per template vertex on the first frame's surface (the dense rig
#: of issue 56 has 16,505 points per frame for the default 10,000-vertex template).
DENSIFIED_POINTS_PER_VERTEX = 1.6


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
        Multiplies ``delta`` (the 4D distance between consecutive frames, ``s``); the
        paper's choice is 1. The default 2 spreads the frames further apart in 4D so that a
        leaf's support spans fewer frames and ``f(., t)`` lags less behind fast motion
        (measurements: benchmarks/METHODS.md).
    cell_size : float
        Urshape marching-cubes cell size; 0: chosen from the first frame's surface area so
        that the urshape has about ``template_vertices`` vertices.
    template_vertices : int
        Target size of the urshape when ``cell_size`` is 0; on sparse frames without
        ``densify`` fewer (at most one per point of the median frame: a template denser than
        its data loses limbs).
    densify : bool
        On sparse frames (the median frame has fewer points than ``template_vertices``), mesh
        every frame on its own and sample its surface at 1.6 points per template vertex
        (:mod:`fourd.geometry.densify`; holes stay holes), so that the fit, the data term and
        the large-motion registration work at the template's resolution; false: the template
        shrinks to the data instead (measurements: benchmarks/METHODS.md).
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
        window by window with ``window_overlap`` extra frames on each side. A streamed run
        (``--stream``, :func:`~fourd.methods.kinematic.reconstruct_streamed`) also reads the
        frames and writes the result per window (0 there: 20 frames).
    window_overlap : int
        Extra frames on both sides of each window that its 4D fit takes in (with ``window``),
        so that ``f`` is continuous enough across the windows' boundaries.
    outlier_factor : float
        Per-frame outlier removal: drop points whose mean distance to their 8 nearest
        neighbours exceeds this multiple of the median of that distance (0: keep all).
    normals_k : int
        Neighbours for PCA normals when the input has none.
    fit_stride : int
        Every ``fit_stride``-th cleaned point of each frame enters the 4D fit (1: all; the
        default 2 takes about half the fit's time). The data term, the spacing and the
        observed flags still use every point.
    data_term : bool
        At output times that are input times, register, project and constrain the observed
        vertices against that frame's own points (an IMLS surface, :mod:`.framesurface`)
        instead of the 4D implicit, whose zero set lags a little behind or ahead of each
        frame; the 4D implicit still fills holes, links the frames and gives the urshape
        (beyond the paper; on by default).
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
        Weight in [0, 1) of the previous frame's shape in the large-motion registration's
        as-rigid-as-possible term (``RegisterOptions.previous_shape``; 0, the default: the
        template's rest shape alone). 0.5 suits captured people and animals, whose skin
        stretches and twists.
    slide_memory : float
        Weight in [0, 1) of the previous frame's shape in the sliding's as-rigid-as-possible
        term (``SlideOptions.previous_shape``; 0, the default: the urshape alone, the
        paper). It helps shapes that stretch, not crane itself (measurements:
        benchmarks/METHODS.md).
    still_normals : float
        With the data term: where the 4D implicit moves less than this many median edges per
        step, constraint (2) takes its normal from the implicit, which is smooth over time,
        instead of from the frame's noisy surface, so a still part does not creep along
        itself (``SlideOptions.still_normals``; 0: never).
    temporal_smoothing : int
        Passes of a ``[1/4, 1/2, 1/4]`` filter over the vertex trajectories (time-weighted
        for uneven output times; the first and last frames stay), which takes out the scan
        noise the data term gives every frame (0: none).
    smoothing_motion : float
        The filter keeps out of the shape's accelerations: its step shrinks where a vertex's
        neighbourhood deviates from the neighbouring frames together, and keeps doing so in
        the next frames, by more than this multiple of the median deviation
        (:func:`smooth_trajectories`; 0: the plain filter everywhere).
    times : tuple of float
        Output times (default: the input times). They may lie between or beyond input times.
    seed : int
        Seed for the subsampling of the spacing estimate.
    video_anchors : bool
        When the input has calibrated video (``cameras.json`` and ``video/``), track anchors
        by optical flow between consecutive frames (:func:`fourd.appearance.anchors`) and
        start each sliding step where they went (:mod:`fourd.appearance.guide`); silent without video. Only
        anchors that start on hue texture count (``anchor_texture``): on low-contrast skin or a
        uniform colour the flow follows the shading, and those anchors misled the performer
        (benchmarks/METHODS.md).
    anchor_pull : float
        With ``video_anchors``: how strongly each step's as-rigid-as-possible solve pulls the
        vertices with anchors towards where the anchors went, in units of the vertex's own
        stiffness (0: the anchors only move the start of the step).
    color_guide : bool
        When the input points have colours, or have none but the input has calibrated video
        (then every frame's points are coloured from the cameras that see them,
        :mod:`fourd.appearance.point_colors`), with or without video anchors: at every input
        frame, after the step, pull each vertex where the colours the template took from the
        first frame say it went (per-vertex Lucas-Kanade on the frame's coloured points,
        :mod:`fourd.appearance.color_guide`) with ``anchor_pull``, and relax again. Only the colours' hue
        counts (the lamps' shading moves with the lamps, not with the skin) and only where it
        stands out of the colour noise, so a uniform colour and smooth skin change little;
        silent without colours or video (benchmarks/METHODS.md).
    color_radius : float
        Patch radius of that Lucas-Kanade, in template edges.
    color_scale : float
        A vertex whose colour shift has this uncertainty (template edges) counts exp(-1); the
        weight falls as ``exp(-(uncertainty / scale)^2)``.
    anchor_texture : float
        With ``video_anchors``: keep only anchors that start where a camera's image has hue
        texture this many times above the noise (``AnchorOptions.texture``; 0: every anchor).
    anchor_gate : float
        With ``video_anchors``: an anchor whose target lies farther than this many template
        edges from where the step's prediction puts the vertex counts less (Gaussian weight;
        0: every anchor counts fully).
    cache_dir : str or None
        Folder where the finished stages are kept: each prepared frame, the 4D fit (each
        window), the urshape and each slid frame, keyed by the input data and the options
        that act on them; a rerun after an interruption resumes after the last one
        (``fourd reconstruct --cache``). None: nothing is kept.
    """

    mpu_error: float = 0.0
    error_quantile: float = 0.95
    min_points: int = 40
    time_scale: float = 2.0
    cell_size: float = 0.0
    template_vertices: int = 10000
    densify: bool = True
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
    video_anchors: bool = True
    anchor_pull: float = 1.0
    anchor_gate: float = 0.0
    anchor_texture: float = 3.0
    color_guide: bool = True
    color_radius: float = 3.0
    color_scale: float = 0.5
    cache_dir: str | None = None

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
