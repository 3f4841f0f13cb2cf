"""Options of the ``surfels`` method, its contract constants, and the energy weights they
give (:func:`energy_weights`)."""

from __future__ import annotations

import os
from dataclasses import dataclass

from fourd.animation import AnimatedMesh
from fourd.methods.surfels.energy import Weights

#: Merging needs two frames.
MIN_FRAMES = 2
#: One connectivity: one frame's mesh carried to every frame by the surfels (sec. 3.3).
RESULT = AnimatedMesh
#: The options users change first (``fourd options surfels``).
URSHAPE_STAGES = ("final", "merges", "rest", "off")
COMMON_OPTIONS = ("sampling", "noise", "rigid", "accel", "iterations", "final_iterations")


@dataclass(frozen=True)
class Options:
    """Options of the ``surfels`` method (Wand et al. 2007). Lengths in input units; 0 means
    "derive from the data" (``s``: the median nearest-neighbour spacing of the first frame).

    Every weight is relative: position terms are multiplied by ``1 / noise^2`` and normal
    terms by ``eps_sampl^2 / noise^2``, so a weight of 1 balances one data point at one noise
    level (eq. 5-10 of the paper).

    Attributes
    ----------
    sampling : float
        ``eps_sampl`` in point spacings ``s`` (the surfels' distance, sec. 3.1); the
        topology radius is ``eps_top = 2 eps_sampl``.
    geodesic : bool
        The shape priors (eq. 6-8) join the surfels that lie within ``eps_top`` of each other
        along the surface, as the paper defines ``T_S`` (sec. 3.1): the length of the arc
        through both that meets their normals (:func:`.topology.build_topology`), so the
        smoothness does not pull the two sides of a limb thinner than ``eps_top`` together.
        The deformation priors (eq. 9, 10) keep every pair within ``eps_top`` in space (a
        limb's cross-section moves rigidly). False: the shape priors too.
    noise : float
        Noise level ``sigma`` in normal direction (input units); 0: ``s`` (the data weight is
        ``omega = 1 / sigma^2``, eq. 5).
    smooth : float
        ``w_smooth^(1)`` (eq. 6), relative.
    smooth_normal : float
        ``w_smooth^(2)`` (eq. 7), relative to ``eps_sampl^2 / sigma^2``.
    tangential : float
        Share ``beta`` of the point-to-surfel distance in the data term of the seed regions
        (:mod:`.match`): it holds each surfel among its data; with the tangent-plane distance
        alone (0) the surfels of one frame slide along the surface and open patches shrink
        (bending-arm frame 0: the truth seen by the scan 0.040 from the nearest surfel on
        average at 0, 0.019 at 0.05, 0.018 before the optimisation). Never in the alignment
        (:mod:`.align`): there it pins each surfel to the data nearest where it starts.
    linked_tangential : float
        The same share in the hole filling and the global optimisations.
    laplace : float
        ``w_Laplace`` (eq. 8) as a fraction of ``smooth`` (paper: 10%). 0 was 18% faster
        and a little better on rigid-turn at 128 rays, but at 64 rays (280 surfels a frame)
        the correspondence error doubled (benchmarks/METHODS.md), so the paper's value stays.
    rigid : float
        ``w_rigid`` (eq. 9) during the merging, relative.
    rigid_normal : float
        eq. (9) on the normals, relative to ``eps_sampl^2 / sigma^2``.
    accel : float
        ``w_accel`` (eq. 10) during the merging, relative; the paper keeps it small until the
        final pass.
    accel_normal : float
        eq. (10) on the normals, relative to ``eps_sampl^2 / sigma^2``.
    final_rigid : float
        Factor on the rigidity weights in the final global optimisation (sec. 3.2
        "Iteration": increased rigidity to smooth the reconstruction).
    final_accel : float
        Factor on the acceleration weights in that final pass.
    align_data : float
        Weight of one data point in the alignment of two frame ranges (the non-rigid ICP of
        sec. 3.2), relative.
    align_iterations : int
        Gauss-Newton steps of that alignment (each re-associates the data, as ICP does).
    align_percentile : float
        That alignment counts the data points up to this percentile of their distances to
        their surfels (sec. 3.2; paper: 85). 100: every point that passes the 45 degree and
        doublet tests. In a fast motion the farthest points are the limbs that moved most,
        and a lower cutoff leaves them behind.
    part_size : float
        Before that alignment's non-rigid ICP, the surfels are split into parts of about this
        many ``eps_sampl`` and each part is searched for rigidly among the data
        (:mod:`.part_search`, beyond the paper): a limb that moved several ``eps_sampl``
        between two scans is beyond nearest-point correspondences. 0: no search (the paper).
    part_reach : float
        The longest translation searched per part, in ``eps_sampl`` (the grid's step is one
        ``eps_sampl``; the cost grows with its cube).
    part_gain : float
        A part moves only when the search puts this fraction of its surfels more within
        ``eps_sampl`` of data of agreeing normal than its start did.
    max_stretch : float
        Stitching filter: an edge whose length changes over its trajectory by more than this
        factor is rejected (paper: 1.5).
    tensor_ratio : float
        Tensor voting: points with second-over-largest eigenvalue ratio above this are not
        in a seed region (paper: 0.8).
    iterations : int
        Gauss-Newton steps of each optimisation during the merging (seed regions, alignment,
        global optimisation of a merged range).
    fill_iterations : int
        Gauss-Newton steps of the local optimisation of each frame filled in.
    merge_reach : int
        Frames on each side of a merge's seam that its global optimisation moves, the frames
        beyond held (the far frames' new surfels keep their hole filling's local
        optimisation, and the final pass optimises every frame); 0: every frame of the
        merged range, as the paper does (2 left more surfels and scored worse on crane:
        benchmarks/METHODS.md).
    final_iterations : int
        Gauss-Newton steps of the final global optimisation of all frames (0: no final
        pass, and no urshape unless the merges computed one).
    last_merge_optimised : bool
        The last merge ends with its global optimisation of every frame, as the paper does;
        false: when the final pass has at least ``iterations`` steps, it starts from the
        merged model straight away (the merges' optimisation keeps the next level's
        resampling at ``eps_sampl``, and after the last merge no resampling follows; a
        shorter final pass left touching-spheres' filled surfels glued across the contact).
        Streamed windows always optimise theirs.
    urshape : str
        When the urshape is computed (sec. 3.2, :mod:`.urshape`): ``"final"`` optimised with
        the trajectories after the final global optimisation; ``"merges"`` as the paper does,
        with the trajectories after the global optimisation of every merge (from scratch at
        each level) and after the final one; ``"rest"`` after the final one, the trajectories
        held (the frames are those of ``"off"``); ``"off"``: none, and the reference frame's
        mesh is the result's ``rest``.
    cg_tolerance : float
        Relative residual at which each step's conjugate gradients stop.
    cg_iterations : int
        Most conjugate-gradient iterations per step (an inexact Newton step: rigid-turn, 4
        frames of 6 degrees at 128 rays, 200 -> 50 took 135 -> 71 s for correspondence
        0.0035 / 0.0051 -> 0.0039 / 0.0058, mean / last; benchmarks/METHODS.md).
    mesh_sigma : float
        Meshing (sec. 3.3): Gaussian window in ``eps_sampl``.
    mesh_cell : float
        Meshing: marching-cubes cell in ``eps_sampl``.
    mesh_clip : float
        Meshing: border clipping threshold (:class:`~.meshing.MeshingOptions` ``clip``).
    mesh_clip_reference : str
        Meshing: what ``mesh_clip`` is relative to, ``"local"`` (the weight the surfels
        around a point have at themselves) or ``"median"`` (the median over all surfels,
        which clips the sparser parts of a model; :class:`~.meshing.MeshingOptions`
        ``clip_reference``).
    fit_frames : bool
        Move every frame's mesh vertices along their normals onto that frame's preprocessed
        points (:func:`fourd.geometry.surface_fit.fit_along_normals`), so the surface is the
        data's where there is data, not the blend of surfel planes ``eps_sampl`` apart; the
        vertices do not move along the surface, so the correspondences stay. Off: the
        paper's mesh.
    fit_radius : float
        Width of that fit's Gaussian weights along the surface, in point spacings ``s``.
    fit_reach : float
        The fit ignores points farther than this from a vertex's tangent plane and moves no
        vertex farther, in point spacings ``s``.
    close_holes : float
        Close the result's holes whose flat area is at most this fraction of their piece's
        (found in the reference frame; :func:`fourd.geometry.hole_closing.close_small_holes`)
        by the membrane of 004 sec. 3.6.2, placed in every frame from that frame's rim and
        not ``observed``: the surface no frame saw, and the stretches the border clipping
        opened. 0: the paper's open mesh.
    close_smoothness : float
        Weight of that membrane's C1 terms (1: the thesis' membrane, continuing the rim's
        slopes; 0: the flat one).
    min_piece : int
        Pieces of the surfel graph (connected components of ``T_S``) with fewer surfels than
        this that have no data in some frame are left out of the mesh: with no neighbours,
        their trajectory there is the acceleration prior's extrapolation, and one lost early
        in a long take flies off (:func:`~.model.unsupported_pieces`). 0: every surfel is
        meshed (the paper). Streamed (``window``), judged on the first window's frames.
    video_anchors : bool
        When the input has calibrated video (``cameras.json`` and ``video/``), track anchors
        by optical flow between consecutive frames (:func:`fourd.appearance.anchors`, on hue
        texture only) and pull each surfel to move as the anchors near it did, in the
        alignments, the hole filling and the global optimisations (:mod:`.anchors`; beyond the
        paper, whose data term says nothing along the surface). Silent without video.
    anchor_weight : float
        Weight of an anchor of confidence 1, relative (as the data points' weights).
    color_guide : bool
        When the input points have colours, or have none but the input has calibrated video
        (then each frame's points are coloured from the cameras that see them,
        :func:`fourd.appearance.color_guide.guide_colors`): in the global optimisations, pull
        each surfel in every frame where the colours its patch had in the first frame that
        observed it say it is (per-surfel Lucas-Kanade on the frame's coloured points, hue
        only; :mod:`.color_guide`, beyond the paper). One reference, so the anchors' small
        errors do not add up from frame to frame. Silent without colours or video. Streamed
        (``window``), the mesh's surfels keep the reference colours of the first window
        (:mod:`.stream`).
    color_weight : float
        Weight of a guide of certainty 1, relative to one data point's: a surfel holds about
        ``sampling^2`` points of data (16 at the default ``sampling``), so 16 makes a sure
        guide as strong as a surfel's data.
    color_radius : float
        Patch radius of that Lucas-Kanade, in ``eps_sampl``.
    color_scale : float
        A guide whose shift's uncertainty is this many ``eps_sampl`` gets weight ``exp(-1)``.
    color_merges : bool
        The guide acts in every merge's global optimisation too, so the drift is held before
        the next level builds on it; false: in the final optimisation only.
    color_rounds : int
        With the colours' guide, the final optimisation runs this many times, the guides found
        again from where the one before left the surfels (the Lucas-Kanade starts nearer).
    reference : int
        The frame whose surfels are meshed and carried to every other frame and to the
        urshape (the result's ``rest``; without an urshape, this frame's mesh).
    normals_k : int
        Neighbours for PCA normals when the input has none.
    cache_dir : str or None
        Folder where each preprocessed frame and each merged model are kept, keyed by the
        input data and the options that act on them; a rerun resumes after the last finished
        merge (``fourd reconstruct --cache``). None: nothing is kept.
    workers : int
        Threads that run the assembly's merges side by side, each as soon as its two parts are
        there (:func:`.assembly.assemble`), and the frames' preprocessing and seeds: the same
        result for any count, at the cost of the working sets held at once. 0: one per core,
        at most 2 (more were not measured); 1: one after another.
    window : int
        0: one model over the whole sequence (the paper). N: the capture assembled N frames
        at a time, each window merged onto the last frames of the one before with those held
        (:mod:`.stream`; ``fourd reconstruct --stream``): memory grows with the window, not
        with the capture, and the mesh is that of frame 0's surfels (``reference`` 0).
    """

    sampling: float = 4.0
    geodesic: bool = True
    noise: float = 0.0
    smooth: float = 0.5
    smooth_normal: float = 0.01
    tangential: float = 0.05
    linked_tangential: float = 0.05
    laplace: float = 0.1
    rigid: float = 1.0
    rigid_normal: float = 1.0
    accel: float = 0.1
    accel_normal: float = 0.01
    final_rigid: float = 4.0
    final_accel: float = 4.0
    align_data: float = 1.0
    align_iterations: int = 12
    align_percentile: float = 100.0
    part_size: float = 4.0
    part_reach: float = 6.0
    part_gain: float = 0.2
    max_stretch: float = 1.5
    tensor_ratio: float = 0.8
    iterations: int = 4
    fill_iterations: int = 2
    merge_reach: int = 0
    final_iterations: int = 4
    last_merge_optimised: bool = False
    urshape: str = "rest"
    cg_tolerance: float = 1e-3
    cg_iterations: int = 50
    mesh_sigma: float = 0.75
    mesh_cell: float = 0.5
    mesh_clip: float = 0.4
    mesh_clip_reference: str = "local"
    fit_frames: bool = True
    fit_radius: float = 2.0
    fit_reach: float = 4.0
    close_holes: float = 0.25
    close_smoothness: float = 1.0
    min_piece: int = 8
    video_anchors: bool = True
    anchor_weight: float = 1.0
    color_guide: bool = True
    color_weight: float = 16.0
    color_radius: float = 3.0
    color_scale: float = 0.5
    color_merges: bool = True
    color_rounds: int = 2
    reference: int = 0
    normals_k: int = 16
    cache_dir: str | None = None
    workers: int = 0
    window: int = 0

    def __post_init__(self):
        for name in (
            "sampling",
            "max_stretch",
            "mesh_sigma",
            "mesh_cell",
            "cg_tolerance",
            "fit_radius",
            "fit_reach",
            "color_radius",
            "color_scale",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in (
            "noise",
            "smooth",
            "smooth_normal",
            "laplace",
            "rigid",
            "rigid_normal",
            "accel",
            "accel_normal",
            "final_rigid",
            "final_accel",
            "align_data",
            "part_size",
            "part_reach",
            "part_gain",
            "close_holes",
            "close_smoothness",
            "anchor_weight",
            "color_weight",
        ):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must not be negative, got {getattr(self, name)}")
        if not 0 < self.align_percentile <= 100:
            raise ValueError(
                f"align_percentile must be in (0, 100], got {self.align_percentile}"
            )
        if not 0 < self.tensor_ratio <= 1 or not 0 < self.mesh_clip < 1:
            raise ValueError("need 0 < tensor_ratio <= 1 and 0 < mesh_clip < 1")
        if self.mesh_clip_reference not in ("local", "median"):
            raise ValueError(
                "mesh_clip_reference must be 'local' or 'median', "
                f"got {self.mesh_clip_reference!r}"
            )
        for name in (
            "iterations",
            "align_iterations",
            "fill_iterations",
            "merge_reach",
            "final_iterations",
            "cg_iterations",
            "min_piece",
            "workers",
            "window",
        ):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must not be negative")
        if int(self.workers) != self.workers:
            raise ValueError(f"workers must be a whole number (0: one per core), got {self.workers!r}")
        if self.color_rounds < 1:
            raise ValueError(f"color_rounds must be at least 1, got {self.color_rounds}")
        if self.urshape not in URSHAPE_STAGES:
            raise ValueError(
                f"urshape must be one of {', '.join(URSHAPE_STAGES)}, got {self.urshape!r}"
            )
        if self.normals_k < 3:
            raise ValueError(f"normals_k must be at least 3, got {self.normals_k}")


def worker_threads(options: Options) -> int:
    """The threads that run the merges and the per-frame stages side by side
    (``options.workers``; 0: one per core, at most 2)."""
    return options.workers or max(1, min(2, os.cpu_count() or 1))


def energy_weights(
    options: Options, noise: float, sampling: float, *, final: bool = False
) -> Weights:
    """The :class:`~.energy.Weights` of eq. (3) for ``options`` at noise level ``noise`` and
    ``eps_sampl`` ``sampling`` (input units); ``final`` scales rigidity and acceleration by
    ``final_rigid`` and ``final_accel`` (the last global optimisation, sec. 3.2)."""
    position = 1.0 / noise**2
    normal = sampling**2 / noise**2
    rigid = options.final_rigid if final else 1.0
    accel = options.final_accel if final else 1.0
    return Weights(
        match=position,
        smooth_position=options.smooth * position,
        smooth_normal=options.smooth_normal * normal,
        laplace=options.laplace * options.smooth * position,
        rigid=rigid * options.rigid * position,
        rigid_normal=rigid * options.rigid_normal * normal,
        accel=accel * options.accel * position,
        accel_normal=accel * options.accel_normal * normal,
        anchor=options.anchor_weight * position if options.video_anchors else 0.0,
        guide=options.color_weight * position if options.color_guide else 0.0,
    )
