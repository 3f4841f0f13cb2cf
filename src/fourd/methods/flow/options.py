"""Options of the ``flow`` method and its fixed constants."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from fourd.animation import MeshSequence

MIN_FRAMES = 2
RESULT = MeshSequence
#: The options users change first (``fourd options flow``; the others under ``--all``).
COMMON_OPTIONS = (
    "resolution",
    "time_substeps",
    "missing_frames",
    "mass_levels",
    "regularize_towards",
    "cavities",
)
#: From this ``resolution`` on a thick object is many cells thick: the automatic
#: ``fit_offset``, ``deep_inside`` and ``still_interior`` switch to their fine-grid values
#: (see :class:`Options`).
FINE_RESOLUTION = 48
#: ``mass_levels`` tells observed from unobserved parts in cells of this resolution, or in the
#: grid's own where it is coarser (see ``Options.observed_distance``).
OBSERVED_RESOLUTION = 32


@dataclass(frozen=True)
class Options:
    """Options of the flow method (defaults follow the paper where it gives a value).

    Attributes
    ----------
    resolution : int
        Flow grid cells along the longest side of the data's bounding box (64 in the paper;
        32 by default here, about 4 times faster with the same quality on the standard
        scenes; measurements: benchmarks/METHODS.md).
    neighbourhood : int
        Temporally adjacent cells a cell's material may flow to: 27 (the paper's Figure 2) or
        7 (the cell and its face neighbours; faster, motion only along axes per step).
    time_substeps : int
        Solution slices per frame interval (1, the default: one slice per frame; 2: one
        empty slice between frames, the paper's solution grid finer than the data, halving
        the speed bound; 0: automatic, see ``motion_limit``). Material moves at most one
        cell per slice, so faster motion leaves cavities, logged as a warning.
    motion_limit, max_substeps : float, int
        With ``time_substeps=0``: the slices per frame interval that bring the 75th percentile
        over frame pairs of the data's motion (99th percentile of the nearest-point
        distances between consecutive frames, :func:`~.grid.frame_motion`) to at most
        ``motion_limit`` cells per slice, at most ``max_substeps``.
    missing_frames : tuple of int
        Frames whose points are ignored (reconstructed from the flow only, Figure 6).
    alpha : float
        Weight of spatial continuity against flow momentum (1/3 in 3D x time).
    regularization : float
        Weight of the regulariser F_r (0.0025).
    regularize_towards : str
        ``"zero"`` (the default, the paper: ``F_r = sum x^2 + sum v^2``) or ``"previous"``
        (``sum (x - x_0)^2 + sum v^2`` with ``x_0`` each solve's starting values: the
        implicit fit's inside indicator, then the previous iterate). Use ``"previous"`` for
        objects with a large unseen convex side (resting on a floor, seen from above), which
        pulling towards zero empties.
    exponent : float
        Norm exponent of the continuity functional (0.8).
    weight_floor, weight_scale : float
        IRLS weights are ``|dx|^(exponent-2)`` with ``|dx| >= weight_floor`` (0.001), scaled
        into ``(0, weight_scale]`` (10).
    clamp : float
        Free cells within ``clamp`` of 0 or 1 after a solve become hard constraints.
    stop_fraction : float
        Stop the IRLS once this fraction of the hull's cells is decided (0.9-0.95).
    max_iterations : int
        Upper bound on IRLS iterations (default 3). With the standard scans the loop reaches
        it before ``stop_fraction``, and the frames no longer change past 3 iterations.
    gamma : float
        Preconditioner parameter (1).
    softness : float
        ``eps`` of the (2,2) block ``-eps I`` (0 in the paper; see :mod:`.saddle`).
    outer_rtol, inner_rtol : float
        MINRES tolerance (1e-3..1e-5) and inner CG tolerance (1e-6).
    inner : str
        Inner solver: ``"cg-amg"`` (CG + classical AMG to ``inner_rtol``, the paper's exact
        inner solve), ``"cg-ilu"`` (CG + incomplete factorisation, drop tolerance 0.01; slow
        set-up in scipy), ``"amg"`` (one V-cycle; the default, for speed).
    max_outer : int
        MINRES iteration limit per solve (40 by default: an inexact, warm-started solve per
        IRLS iteration; raise it with ``inner="cg-amg"`` for the paper's tolerances).
    later_outer : int
        MINRES iteration limit of the IRLS solves after the first, which start from the
        previous solve's values and flows (0, the default: ``max_outer``). 10 makes the
        method 20-35% faster, but the truncated later solves conserve mass less well.
    reuse_interpolation : bool
        With ``inner="amg"``, IRLS iterations after the first keep the previous V-cycle's
        AMG interpolation, restricted to the unknowns still free, and only recompute the
        coarse matrices (half the set-up; the same MINRES residual on the captured crane
        systems, see :func:`.saddle.solve_saddle`). False: a new set-up every iteration.
    reuse_coarse : bool
        With ``reuse_interpolation`` (the default, true): keep the previous solve's coarse
        matrices too (restricted to the unknowns still free), so that the later solves never
        form ``A + B^T B`` nor its Galerkin products; only the finest level's sweeps see the
        new system (see :func:`.saddle.solve_saddle` ``reuse_coarse``).
    interpolation_entries : int
        With ``inner="amg"``: keep only this many largest entries per row of the V-cycle's
        AMG interpolations (0: all, the default). Fewer entries make each MINRES step
        cheaper and use less memory, but the solutions conserve mass less well.
    coarse_drop : float
        With ``inner="amg"``: drop the off-diagonal entries ``|a_ij| < coarse_drop sqrt(a_ii
        a_jj)`` of the V-cycle's coarse matrices, lumped onto their diagonals (0: none, the
        default; :func:`.sparse.drop_weak_entries`). Faster V-cycles at about the same
        residual, but worse output, so it is off by default.
    parallel_sweeps : bool
        With ``inner="amg"``: the V-cycle's Gauss-Seidel sweeps run on all cores, blocks of
        time slices that share no entry at once (:mod:`.sweeps`: Gauss-Seidel in another row
        order, the same on any number of cores). False: rows one after the other in the
        system's own order.
    outward_cosine : float
        A face of a data cell is an outward boundary face (first-iteration weight 0) when the
        cell's mean normal makes a cosine above this with the face direction.
    fit_level : float
        Local extrema of the implicit fit beyond +-``fit_level`` relabel cells (fit values are
        +1 on carved cells, -1 targets at seeds).
    fit_offset : float or None
        Offset points of the implicit fit, this many flow cells in along each data point's
        normal (see :mod:`.fit`; 0: none, as the paper). None, the default: 1 at
        ``resolution`` 48 and above, none below, so that a thick object's interior comes out
        negative in the fit and is labelled inside.
    deep_inside : float or None
        Cells where the implicit fit is negative and that lie at least this many flow cells
        from every carved and every data cell are labelled inside too (0: only the fit's
        local minima, as the paper; None, the default: 4 below ``resolution`` 48, 2 from 48
        on). A deviation for thick objects, whose interior far from the seeds would
        otherwise stay undecided after ``max_iterations``.
    still_interior : int or None
        Material stays in cells fixed inside at least this many cells deep (and fixed inside
        in the next slice too): their flows to other cells are dropped and their flow to
        themselves is the constant 1 (:func:`.system.still_interior`; 0: flows everywhere,
        the paper; None, the default: 1 from ``resolution`` 48 on, 0 below). A deviation for
        speed: a thick interior only costs unknowns, but a translating thick object's
        boundary layers lag a little.
    outlier_factor : float
        Statistical outlier filter: drop points whose 8th-neighbour distance exceeds this
        multiple of the median.
    refine : int
        Refinement factor of the postprocessing band (fine spacing ``h / refine``).
    band : float
        Half-width of the refined band around the flow surface, in flow cells.
    smoothness : float
        Weight of the Laplace term of the postprocessing (per 4D edge, against weight 1 of
        the data targets; default 0.1). Its edges include time, so a strong term blends each
        frame's surface with its neighbours' and smooths the zero level off the data.
    time_smoothness : float
        Weight of the Laplace term's temporal edges between two slices that both have data,
        relative to its spatial edges (the paper's 4D Laplace solve: 1; default 0). Edges
        touching a slice without data (a missing frame, a sub-step slice) keep weight 1, so
        such slices are still filled from their neighbours; where a part moves by more than
        its thickness per frame, weight 1 pulls it off its data.
    min_component : float
        Closed components with volume below this fraction of the frame's largest are dropped.
    hull_trim : bool
        Before the postprocessing, empty the cells outside a tighter visual hull (the
        sampling's gaps and a one-pixel rim filled instead of a three-pixel rim, see
        :func:`~.grid.carve_visual_hull`). The flow itself keeps the wider hull (solving with
        the tighter one pulls material out of the interior where the motion is fast), but
        where it parks material in the rim above a grazing view, the output would bulge.
    cavities : bool
        Keep closed cavities inside the solid (inner surfaces, negative enclosed volume).
        Off by default: no scanner outside the object sees one, so a cavity is the flow's
        doing (motion faster than one cell per time step).
    mass_levels : bool or "auto"
        For incompressible objects: move the unobserved parts of each frame's mesh along
        their normals so that its enclosed volume follows the flow's conserved mass
        (:func:`mass_meshes`; a deviation from the paper, which contours the zero level).
        ``"auto"`` (the default) applies the offsets only when no frame asks its unobserved
        parts to move by more than the object's mean radius ``3 V / A`` (:func:`mass_meshes`
        ``all_or_nothing``), that is when the parts no scanner saw can account for the
        frames' volume differences.
    observed_distance : float
        With ``mass_levels``: vertices within this many flow cells of a data point of their
        frame stay; the offset's weight rises to 1 over the next flow cell. Above resolution
        32 the cells of this test are those of resolution 32 (the longest side / 32), so the
        same parts count as observed on a finer grid.
    level_limit : float
        With ``mass_levels``: the largest offset of a frame's unobserved parts, in flow cells
        (``squash-ball`` at resolution 32 needs up to 3.2). Large offsets can make concave
        unseen parts self-intersect.
    unobserved_smoothing : int
        With ``mass_levels``: umbrella smoothing steps of the unobserved parts before the
        offset (default 100). Steps are per mesh edge, so the smoothed distance shrinks with
        finer meshes (higher ``resolution``); each frame's steps are scaled by how far its
        volume is off, its first offset in flow cells, at most 1 (:func:`mass_meshes`).
    window : int
        Frames per flow solve (0: one solve over the whole sequence). A longer sequence is
        solved window by window, consecutive windows sharing at least ``window_overlap``
        frames, and each shared frame's mesh is the zero set of the two windows' signed
        distances blended by its place in the overlap, so the surface passes from one solve
        to the next without a jump. Memory is then bounded by the window, and each window's
        grid fits its own frames (``fourd.methods.flow.windows``). A streamed run
        (``--stream``) also reads the frames and writes the meshes per window (0 there: 20
        frames). ``watertight`` runs its kinematic and flow stages window by window too, the
        flow's windows as here (0 in memory: one solve; streamed: 20 frames).
    window_overlap : int
        Frames that consecutive windows share at least (with ``window``), blended from one
        window's surface into the next one's; from 1 to half the window, so that no frame is
        in more than two windows.
    cache_dir : str or None
        Folder where the finished stages are kept: the grid, visual hull and initial labels,
        each IRLS iteration while the solve runs (with the AMG hierarchy the next one reuses,
        so a resumed solve gives the same result), the solve's result and the meshes, keyed
        by the input data and the options that act on them; a rerun after an interruption
        resumes after the last one (``fourd reconstruct --cache``). In windows (``window``)
        each finished window is kept instead. None: nothing is kept.
    """

    resolution: int = 32
    neighbourhood: int = 7
    time_substeps: int = 1
    motion_limit: float = 1.0
    max_substeps: int = 4
    missing_frames: tuple[int, ...] = ()
    alpha: float = 1.0 / 3.0
    regularization: float = 0.0025
    regularize_towards: Literal["zero", "previous"] = "zero"
    exponent: float = 0.8
    weight_floor: float = 0.001
    weight_scale: float = 10.0
    clamp: float = 0.05
    stop_fraction: float = 0.93
    max_iterations: int = 3
    gamma: float = 1.0
    softness: float = 1e-3
    outer_rtol: float = 1e-3
    inner_rtol: float = 1e-6
    inner: Literal["cg-amg", "cg-ilu", "amg"] = "amg"
    max_outer: int = 40
    later_outer: int = 0
    reuse_interpolation: bool = True
    reuse_coarse: bool = True
    interpolation_entries: int = 0
    coarse_drop: float = 0.0
    parallel_sweeps: bool = True
    outward_cosine: float = 0.5
    fit_level: float = 0.5
    fit_offset: float | None = None
    deep_inside: float | None = None
    still_interior: int | None = None
    outlier_factor: float = 3.0
    refine: int = 2
    band: float = 2.0
    smoothness: float = 0.1
    time_smoothness: float = 0.0
    min_component: float = 0.02
    cavities: bool = False
    hull_trim: bool = True
    mass_levels: bool | Literal["auto"] = "auto"
    observed_distance: float = 0.5
    level_limit: float = 4.0
    unobserved_smoothing: int = 100
    window: int = 0
    window_overlap: int = 4
    cache_dir: str | None = None

    def __post_init__(self):
        if self.resolution < 4:
            raise ValueError(f"resolution must be at least 4, got {self.resolution}")
        if self.later_outer < 0:
            raise ValueError(f"later_outer must be 0 (max_outer) or more, got {self.later_outer}")
        if self.interpolation_entries < 0:
            raise ValueError(
                f"interpolation_entries must be 0 (all) or more, got {self.interpolation_entries}"
            )
        if not 0.0 <= self.coarse_drop < 1.0:
            raise ValueError(f"coarse_drop must be in [0, 1), got {self.coarse_drop}")
        if self.neighbourhood not in (7, 27):
            raise ValueError(f"neighbourhood must be 7 or 27, got {self.neighbourhood}")
        if self.time_substeps < 0:
            raise ValueError(f"time_substeps must be 0 (automatic) or more, got {self.time_substeps}")
        if self.max_substeps < 1 or self.motion_limit <= 0:
            raise ValueError(
                f"max_substeps must be at least 1 and motion_limit positive, got "
                f"{self.max_substeps}, {self.motion_limit}"
            )
        if not 0 < self.alpha < 1:
            raise ValueError(f"alpha must be in (0, 1), got {self.alpha}")
        if not 0 < self.stop_fraction <= 1:
            raise ValueError(f"stop_fraction must be in (0, 1], got {self.stop_fraction}")
        if not 0 <= self.clamp < 0.5:
            raise ValueError(f"clamp must be in [0, 0.5), got {self.clamp}")
        if self.refine < 1:
            raise ValueError(f"refine must be at least 1, got {self.refine}")
        if self.still_interior is not None and self.still_interior < 0:
            raise ValueError(f"still_interior must not be negative, got {self.still_interior}")
        if self.deep_inside is not None and self.deep_inside < 0:
            raise ValueError(f"deep_inside must not be negative, got {self.deep_inside}")
        if self.fit_offset is not None and self.fit_offset < 0:
            raise ValueError(f"fit_offset must not be negative, got {self.fit_offset}")
        if self.regularize_towards not in ("zero", "previous"):
            raise ValueError(
                f"regularize_towards must be zero or previous, got {self.regularize_towards!r}"
            )
        if self.mass_levels not in (True, False, "auto"):
            raise ValueError(f"mass_levels must be true, false or auto, got {self.mass_levels!r}")
        if self.inner not in ("cg-amg", "cg-ilu", "amg"):
            raise ValueError(f"inner must be cg-amg, cg-ilu or amg, got {self.inner!r}")
        if self.observed_distance < 0 or self.level_limit < 0 or self.unobserved_smoothing < 0:
            raise ValueError(
                f"observed_distance, level_limit and unobserved_smoothing must not be negative, "
                f"got {self.observed_distance}, {self.level_limit}, {self.unobserved_smoothing}"
            )
        for name in ("regularization", "softness", "band", "smoothness", "time_smoothness", "gamma"):
            if getattr(self, name) < 0 or (name in ("band", "gamma") and getattr(self, name) == 0):
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if self.window < 0 or (self.window and not 1 <= self.window_overlap <= self.window // 2):
            raise ValueError(
                f"window must be 0 (one solve) or at least 2, with window_overlap from 1 to half "
                f"the window; got {self.window} and {self.window_overlap}"
            )
        object.__setattr__(self, "missing_frames", tuple(int(i) for i in self.missing_frames))
