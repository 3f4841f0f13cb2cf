"""Settings of the assembly method: the pair map's (thesis sections 5.4.2-5.4.4) and the
method's own :class:`Options` (5.3, 5.6)."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from fourd.geometry.frame_surface import SurfaceSettings

#: Frames of at least this many vertices have their merges run one per core by default
#: (``Options.workers`` 0): a crane frame (35,000 vertices) merges in about 25 s, where
#: starting a worker process costs a few seconds.
PARALLEL_VERTICES = 5000

#: Frames per window of a streamed run when ``Options.window`` is 0: each seam re-anchors the
#: chain of maps to the fitted frame, so shorter windows drift less (1,000 sparse frames:
#: correspondence 0.018 / 0.025 at 8, 0.028 / 0.041 at 16, and no slower).
STREAM_WINDOW = 8

#: A sequence of more frames than this runs in windows of :data:`STREAM_WINDOW` in memory too
#: when ``Options.window`` is 0 (:meth:`Options.window_for`): over a long take the windows'
#: fitted seams keep the chain of maps from wearing, while a short one gains nothing from them
#: and loses merges run side by side (sparse ping-pong crane at 80 frames 0.0124 / 0.0170 ->
#: 0.0119 / 0.0152, at 40 the same; 20 dense crane frames the same, 3.05 -> 3.63 s/frame).
WINDOWED_FRAMES = 32

#: Named sources of anchors (``Options.anchors``; else the path of an anchors file).
ANCHOR_SOURCES = ("auto", "geometry", "video")


@dataclass(frozen=True)
class CrossParamOptions:
    """Settings of :func:`~fourd.methods.assembly.crossparam.cross_parameterize`.

    Attributes
    ----------
    patch_anchors : int
        A patch stops growing once it holds this many matching anchors (the thesis: three to
        five; more make the alignment less sensitive to anchor noise).
    min_anchors : int
        A patch that reaches ``max_radius`` with fewer matching anchors is discarded (three
        fix a planar affine map).
    max_radius : float
        Largest geodesic patch radius, as a fraction of the source mesh's bounding-box
        diagonal: larger patches are not near-isometric enough to align (5.4.2, "Patch
        Growth").
    boundary_band : float
        Fraction of a patch's radius, next to its boundary, whose map is ignored (the
        alignment is worst there; 5.4.2, "Patch Cross-Parameterization").
    flattening : {"abf", "lscm"}
        How patches are laid out in the plane: ABF++ (the thesis' choice) or LSCM.
    max_residual : float
        A patch pair whose aligned anchors stay farther apart than this fraction of the
        patch's radius (RMS, in the plane) is given up: the patches do not match (measured on
        bending-arm frames 0 and 3 remeshed apart: median 0.006, largest 0.047; frames 0
        and 7: largest 0.12).
    centre_spacing : float
        The first pass grows pairs around anchors at least this far apart on the source
        (source median edges; :func:`~fourd.methods.assembly.anchors.spread_anchors`); 0:
        around every anchor, as the thesis does. A patch holds several anchors, so pairs
        around all of them cover each vertex many times over.
    """

    patch_anchors: int = 4
    min_anchors: int = 3
    max_radius: float = 0.2
    boundary_band: float = 0.25
    flattening: str = "abf"
    max_residual: float = 0.2
    centre_spacing: float = 0.0

    def __post_init__(self):
        if int(self.min_anchors) != self.min_anchors or self.min_anchors < 3:
            raise ValueError(f"min_anchors must be an integer >= 3, got {self.min_anchors!r}")
        if int(self.patch_anchors) != self.patch_anchors or self.patch_anchors < self.min_anchors:
            raise ValueError(
                f"patch_anchors must be an integer >= min_anchors ({self.min_anchors}), "
                f"got {self.patch_anchors!r}"
            )
        if not 0 < self.max_radius <= 1:
            raise ValueError(f"max_radius must be in (0, 1], got {self.max_radius!r}")
        if not 0 <= self.boundary_band < 1:
            raise ValueError(f"boundary_band must be in [0, 1), got {self.boundary_band!r}")
        if not self.max_residual > 0:
            raise ValueError(f"max_residual must be > 0, got {self.max_residual!r}")
        if self.flattening not in ("abf", "lscm"):
            raise ValueError(f"flattening must be 'abf' or 'lscm', got {self.flattening!r}")
        if not (np.isfinite(self.centre_spacing) and self.centre_spacing >= 0):
            raise ValueError(f"centre_spacing must be non-negative, got {self.centre_spacing!r}")


@dataclass(frozen=True)
class RelaxOptions:
    """Settings of :func:`~fourd.methods.assembly.relax.relax_map` (thesis section 5.4.3).

    Attributes
    ----------
    sweeps : int
        Global sweeps over all vertices (the thesis: five to six).
    walks : int
        Random directions tried per vertex and step (the thesis: about a hundred random walks
        per vertex). Half are line searches: walked over the target to the point along them
        nearest the vertex's Laplacian optimum; half walk a random length, log-uniform from a
        hundredth of a source edge to one edge, which is what frees a flipped sliver (on
        bending-arm frames 0 and 3 remeshed apart, from a map slid by 0.4 edges: 12 flipped
        triangles left after 6 sweeps with line searches only, none with both). The steepest
        direction is always tried beside them. 8 (the default) against 16: crane's
        correspondence 0.0065 / 0.0094 -> 0.0064 / 0.0093 in 10% less time; 4 was as good on
        the bench scenes, but left two slivers of 3 and 6 vertices beside the deleted neck
        of ``correct``'s two spheres (``benchmarks/METHODS.md``).
    steps : int
        Moves per vertex in a sweep (each the best of its walks).
    tolerance : float
        The sweeps stop after one that lowered the energy by less than this fraction of the
        energy before the first (0: all ``sweeps`` run).
    laplacian : {"uniform", "cotangent"}
        The source Laplacian ``L``. Uniform by default: per-frame meshes from marching cubes
        have slivers whose cotangent weights run into the hundreds (bending-arm remeshed:
        up to 438, down to -13).
    seed : int
        Seed of the random directions.
    """

    sweeps: int = 6
    walks: int = 8
    steps: int = 2
    tolerance: float = 0.0
    laplacian: str = "uniform"
    seed: int = 0

    def __post_init__(self):
        for name in ("sweeps", "walks", "steps"):
            value = getattr(self, name)
            if int(value) != value or value < (1 if name == "steps" else 0):
                raise ValueError(f"{name} must be a non-negative integer (steps >= 1), got {value!r}")
        if not (np.isfinite(self.tolerance) and 0.0 <= self.tolerance < 1.0):
            raise ValueError(f"tolerance must lie in [0, 1), got {self.tolerance!r}")
        if self.laplacian not in ("uniform", "cotangent"):
            raise ValueError(f"laplacian must be 'uniform' or 'cotangent', got {self.laplacian!r}")


@dataclass(frozen=True)
class RefineOptions:
    """Settings of :func:`~fourd.methods.assembly.refine.refine_anchors` (thesis section
    5.4.4). Lengths are in source edges (the source's median edge length).

    Attributes
    ----------
    touch : float
        An unmapped vertex, registered in the target's frame, becomes an anchor when it lies
        this close to the target ("a nearly zero distance"; the registration places the
        vertices of a hole 6 edges wide about 0.03 edges from the truth, at most 0.1).
    spacing : float
        Anchors added no closer than this to each other or to the anchors there were
        (anchors this far apart are about 3% of the vertices, the thesis' density).
    iterations : int
        Rotation fits of the registration
        (:func:`~fourd.methods.assembly.registration.register_by_laplacian`).
    laplacian : {"uniform", "cotangent"}
        The Laplacian of the registration.
    """

    touch: float = 0.1
    spacing: float = 4.0
    iterations: int = 16
    laplacian: str = "uniform"

    def __post_init__(self):
        for name in ("touch", "spacing"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if int(self.iterations) != self.iterations or self.iterations < 0:
            raise ValueError(f"iterations must be a non-negative integer, got {self.iterations!r}")
        if self.laplacian not in ("uniform", "cotangent"):
            raise ValueError(f"laplacian must be 'uniform' or 'cotangent', got {self.laplacian!r}")


@dataclass(frozen=True)
class PairOptions:
    """Settings of :func:`~fourd.methods.assembly.pair.cross_parameterize_pair`.

    Attributes
    ----------
    crossparam : CrossParamOptions
        The patch map (5.4.2).
    relax : RelaxOptions
        Its relaxation (5.4.3).
    refine : RefineOptions or None
        Anchor refinement (5.4.4) before the patch map; None (the default) skips it. Off
        because it costs accuracy where it is needed: bending-arm frames 0 -> 3 remeshed
        apart, the anchors in an 8-edge disc at the elbow dropped, it maps 97% of the vertices
        instead of 86%, but the map's 95th percentile distance from the truth goes from 0.56
        to 1.22 edges and 2 flips stay (0 -> 7: 1.19 -> 2.44, 5 flips): the anchors it adds
        are 0.3-1.7 edges off. With evenly spread anchors (3%) it adds none.
    refine_radius : float
        The largest patch radius of the first, limited patch map whose unmapped vertices the
        refinement fills (fraction of the source's bounding-box diagonal, as ``max_radius``).
    """

    crossparam: CrossParamOptions = CrossParamOptions()
    relax: RelaxOptions = RelaxOptions()
    refine: RefineOptions | None = None
    refine_radius: float = 0.14

    def __post_init__(self):
        if not 0 < self.refine_radius <= 1:
            raise ValueError(f"refine_radius must be in (0, 1], got {self.refine_radius!r}")


@dataclass(frozen=True)
class Options(SurfaceSettings):
    """Options of the assembly method (thesis chapter 5). Frames that are meshes are used as
    they are; point-cloud frames are first meshed one by one with the settings inherited from
    :class:`~fourd.geometry.frame_surface.SurfaceSettings` (``fourd options perframe``
    describes them). Lengths of the pair maps are in source edges (a mesh's median edge).

    Attributes
    ----------
    anchors : str
        Where each merge's anchors come from besides the geometry (thesis 5.4.1,
        :mod:`~fourd.methods.assembly.guides`): ``geometry``, none (a coarse non-rigid
        alignment and closest points alone); ``video``, the optical-flow anchor tracks of the
        capture's calibrated video (``cameras.json`` and ``video/`` beside the frames), which
        pull the alignment and join its anchors; ``auto`` (the default), ``video`` when the
        input has video and ``color_fit`` is off, else ``geometry``; or the path of an
        ``.npz`` anchors file (its format in :mod:`~fourd.methods.assembly.guides`), used as
        the video's. Without the colour fit the video's anchors cut the bench's drift on
        printed cloth by 2-3 times (bending-arm-cloth-video correspondence 0.0272 / 0.0526 ->
        0.0129 / 0.0239); with it they add 0-40% on the bench's 20-frame close-ups and, chained
        pair after pair, double the drift over the whole 175-frame crane capture filmed from
        afar (``benchmarks/METHODS.md``).
    anchor_texture : float
        With ``anchors="video"``, only tracks that start where the image's hue texture is at
        least this many times the noise's count (0: all; ``kinematic``'s ``anchor_texture``).
    guide_pull : float
        Weight of each video or file anchor in the coarse alignment, in data terms
        (:func:`~fourd.methods.assembly.alignment.nonrigid_icp`'s ``pin_weight``).
    color_fit : bool
        When the input has colours (every frame's points coloured, or calibrated video), slide
        each assembled frame along its own surface to where the first frame's colours are
        (:mod:`~fourd.methods.assembly.color_fit`: per-vertex Lucas-Kanade against the first
        frame, so the pair maps' errors stop adding up); silent without colours. On the
        bench's printed cloth 3-20 times less drift than geometry alone (waving-sheet-cloth-video
        0.0647 / 0.1209 -> 0.0032 / 0.0055), the whole 175-frame crane capture half
        (0.0200 / 0.0353 -> 0.0105 / 0.0203), for 0.3-2 s a frame; none on skin
        (``benchmarks/METHODS.md``).
    rest_fit : int
        At most this many ARAP-ICP rounds per frame slide each assembled frame along its own
        surface towards the shape most as-rigid-as-possible to the first frame
        (:mod:`~fourd.methods.assembly.rest_fit`), before the colour fit; fewer once a round
        barely moves the vertices; 0: off. Each pair map's relaxation keeps its source's shape,
        so its slides and distortions add up along the chain of maps; measured against the
        first frame they do not.
    rest_weight : float
        The frame's surface's pull in that fit, against the ARAP energy (relative to the first
        frame's cotangent Laplacian's mean diagonal): smaller lets the vertices slide further
        along the surface per round.
    color_radius : float
        Patch radius of that Lucas-Kanade, in the assembled mesh's edges.
    color_scale : float
        A vertex whose colour shift has this uncertainty (edges) counts exp(-1); the weight
        falls as ``exp(-(uncertainty / scale)^2)``.
    anchor_spacing : float
        Geometric anchors about this far apart on each source mesh (edges; 2 maps 81% of
        crane's vertices frames 0 -> 4 remeshed apart, 3 and 4 only 54%, at the same error,
        see ``benchmarks/METHODS.md``).
    anchor_gap : float
        An aligned source vertex farther than this from the target is no anchor (edges).
    anchor_tolerance : float
        Forward-backward tolerance of the anchors (edges, thesis 5.4.1).
    alignment_iterations : int
        As-rigid-as-possible ICP iterations of the coarse alignment the anchors come from
        (:func:`~fourd.methods.assembly.alignment.nonrigid_icp`; the 3 nearest-point steps it
        replaced left 0.023 of crane's 0.028 mean step between its bench frames 9 and 10
        unrecovered, see ``benchmarks/METHODS.md``).
    alignment_weight : float
        Its data weight relative to the Laplacian's mean diagonal: smaller is stiffer, a limb
        moving as a whole.
    alignment_coarse : float
        When above 0, that alignment's stiff iterations run on each source of at least
        :data:`~fourd.methods.assembly.alignment.COARSE_VERTICES` vertices decimated by this
        fraction of its faces (0.75: a quarter left), twice as many of them, its last soft
        ones at full resolution
        (:func:`~fourd.methods.assembly.alignment.geometric_anchors`' ``coarse``); 0: all at
        full resolution. Off: 10% faster and better on crane and dfaust-hopping, worse on the
        held-out crane-50 (``benchmarks/METHODS.md``).
    alignment_settle : float
        That alignment's stiff schedule skips to its last three iterations once three in a
        row moved 99% of the vertices less than this (source edges): the template has come to
        rest (:func:`~fourd.methods.assembly.alignment.nonrigid_icp`'s ``settle``); 0: all
        of them run. 0.02: crane 15% and dfaust-hopping 26% faster, dfaust's correspondence
        6% better, crane's and the held-out crane stretches' 1-4% worse
        (``benchmarks/METHODS.md``).
    patch_spacing : float
        The pair maps' first patches grow around anchors at least this far apart (source
        edges; the pair map's ``centre_spacing``); 0: around every anchor (the thesis). 5:
        half the patches and a quarter less time in the patch maps of a crane merge, the same
        map (``benchmarks/METHODS.md``).
    map_agreement : float
        Largest distance (source edges) between a vertex's place by the pair map and by that
        alignment: farther, the two disagree, and the vertex is left to the registration of
        unmapped vertices (unobserved in the right block's frames). Near a hole of the target
        a patch map pressed vertices into the rim's triangles, 2-4.6 edges from where they
        belong; on crane's fastest pair 14 of 35,000 vertices disagree, all of them about 2.5
        edges off.
    max_radius : float
        Largest geodesic patch radius, a fraction of the source's bounding-box diagonal
        (thesis 5.4.2).
    flattening : {"abf", "lscm"}
        How patches are laid out in the plane (5.4.2). LSCM by default: crane frames 0 -> 4
        remeshed apart (4,482 vertices), after relaxation 0.424 / 0.702 edges median / 95th
        percentile from the truth in 9.6 s, ABF++ 0.420 / 0.691 in 25.1 s.
    relax_sweeps : int
        Sweeps of the local relaxation of each pair map (5.4.3; 0 skips it).
    relax_walks : int
        Random walks per vertex and step of the relaxation.
    relax_tolerance : float
        The relaxation stops after a sweep that lowered its energy by less than this fraction
        of the energy it started from (0: every sweep runs). 0.01 saved crane and dfaust-hopping
        6% with the same correspondence, the held-out crane stretches nothing, and cost
        crane-90's last frame 7% (``benchmarks/METHODS.md``), so it is off by default.
    registration_iterations : int
        Rotation fits of the Laplacian registration that places the vertices a pair map
        cannot (thesis 5.6, [LSA+05]).
    correct : bool
        Analyse each pair map (thesis 5.5) and unmap the vertices of its inconsistent regions
        (triangles stretched beyond ``correct_stretch``, vertices moving unlike their
        neighbours by over ``correct_motion`` edges), so the Laplacian registration places
        them from the source's geometry; a region whose placement fails the thesis' stretch
        test is replaced by the target's geometry (with ``paste``) when that passes it, else
        deleted from both. Off: on frames remeshed apart it flags 28-53% of the
        vertices (the maps' edge-length noise) and raises the error's 95th percentile (crane
        0 -> 4: 1.75 -> 4.01 edges, bending-arm 0 -> 3: 6.7 -> 8.8; see ``benchmarks/METHODS.md``).
    correct_stretch : float
        Edge-length ratio beyond which (or below its inverse) a mapped triangle is stretched.
    correct_motion : float
        Motion deviation from the one-ring's mean (edges) that flags a vertex.
    paste : bool
        Glue geometry only the later frame of a merge has (a hole of the earlier frame's scan)
        into the union mesh (thesis 5.6, :mod:`fourd.methods.assembly.completion`): the result
        gains those vertices, unobserved in the frames before. Off (the default): on the
        bench's crane, dfaust-hopping and touching-spheres it lowers completeness-95
        (0.0126 -> 0.0080, 0.0170 -> 0.0158, 0.0589 -> 0.0337), but in the frames that never
        saw it the pasted geometry's shape is a guess from the rim (placed frame by frame by
        Laplacian coordinates), and on the held-out crane stretches it lies off the surface
        (crane-90: Chamfer 0.0036 against 0.0023 off, and a poorer correspondence); see
        ``benchmarks/METHODS.md``.
    paste_gap : float
        A later frame's triangle is geometry the union lacks when its corners lie farther than
        this many edges from the union placed in that frame; the seam band is this wide.
    close_holes : float
        Close the holes no frame filled at the end by the membrane of thesis 3.6.2
        (:func:`fourd.geometry.hole_filling.fill_holes`), placed in every frame from that
        frame's rim, unobserved: every boundary loop whose flat area is at most this fraction
        of the area of the piece of surface it bounds (the first frames' meshes of the bench:
        crane's holes span at most 5% of the body, dfaust-hopping's 3%, touching-spheres'
        unseen facing sides 11% and 16% of their sphere, waving-sheet's outline 94%, kept).
        0 keeps every hole. Use 0 for a garment too: its openings are holes by this test (or
        use the ``garment`` method).
    close_smoothness : float
        Weight of the membrane's C1 terms (3.6.2: the rim's own Laplacian rows, which bend the
        membrane to leave the rim along the surface): 1 the thesis' C1 membrane, 0 the flat
        (C0) one. C1 continues a convex surface (touching-spheres' unseen caps) but also the
        flare of a scanned rim, and a body's occlusion holes sit in its creases, nearer the
        flat membrane. 0.1 (the default) serves both: over 4 frames Chamfer / completeness-95
        crane 0.0023 / 0.0115 open -> 0.0024 / 0.0054 (C1 0.0029 / 0.0072, flat 0.0023 /
        0.0048), touching-spheres 0.0047 / 0.0488 -> 0.0041 / 0.0216 (C1 0.0026 / 0.0076, flat
        0.0061 / 0.0373), dfaust-hopping 0.0026 / 0.0153 -> 0.0027 / 0.0101; see
        ``benchmarks/METHODS.md``.
    open_handles : int
        With ``close_holes``, also cut out the closed mesh's small handles (topological noise:
        a ball of this many edges that is not a disk, :mod:`fourd.geometry.handles`) and fill
        the openings with the same membrane, so that the animation does not keep the tunnels a
        scan's first frame grew between two sheets of skin a few spacings apart. A cut that
        would split the surface (a thin part) is not made. 0 keeps every handle.
    window : int
        Frames per window: the hierarchy runs within windows of this many frames, and each
        window's block is merged onto the result so far, one after another (issue 56), so the
        run needs one window of frames at a time (``fourd reconstruct --stream``, where 0
        takes :data:`STREAM_WINDOW`). 0 (the default, in memory): one hierarchy over a sequence
        of up to :data:`WINDOWED_FRAMES` frames, windows of :data:`STREAM_WINDOW` over a longer
        one (:meth:`window_for`); a window at least as long as the sequence: one hierarchy.
        Every consecutive frame pair is mapped once either way; the windows change
        which frame's connectivity a later map starts from, and each window's frames are
        fitted (``rest_fit``, ``color_fit``) before the next window's seam starts from its last
        frame as fitted, so the chain of maps does not carry its wear past a window (over a
        1,000-frame take its drift stops climbing). ``paste``, ``correct`` and an anchors file
        need the whole sequence at once, so a run in windows refuses them.
    workers : int
        Merges of one level of the hierarchy run in this many processes (they are
        independent, 5.3), with the same result; 1 runs them one after the other; 0 (the
        default) one per core when the frames have :data:`PARALLEL_VERTICES` vertices or
        more, else 1 (starting a process costs more than a small merge).
    scheduler : str
        Where the frames' own surfaces are made (``fourd reconstruct --scheduler``): ``sync``
        here, ``processes`` side by side in local processes, or a ``dask.distributed``
        scheduler's address (``tcp://HOST:PORT``); the same surfaces either way
        (:func:`fourd.pipeline.map_frames`).
    cache_dir : str or None
        Folder where each frame's mesh (point-cloud input), each merge's map and each
        frame's colour fit are kept, keyed by their data and the options that act on them
        (``fourd reconstruct --cache``): a stopped run resumes where it stopped.
    """

    anchors: str = "auto"
    anchor_texture: float = 3.0
    guide_pull: float = 16.0
    color_fit: bool = True
    rest_fit: int = 16
    rest_weight: float = 0.03
    color_radius: float = 5.0
    color_scale: float = 0.5
    anchor_spacing: float = 2.0
    anchor_gap: float = 1.0
    anchor_tolerance: float = 1.5
    alignment_iterations: int = 50
    alignment_weight: float = 0.001
    alignment_coarse: float = 0.0
    alignment_settle: float = 0.02
    patch_spacing: float = 5.0
    map_agreement: float = 2.0
    max_radius: float = 0.2
    flattening: str = "lscm"
    relax_sweeps: int = 6
    relax_walks: int = 8
    relax_tolerance: float = 0.0
    registration_iterations: int = 16
    correct: bool = False
    correct_stretch: float = 2.0
    correct_motion: float = 1.5
    paste: bool = False
    paste_gap: float = 2.0
    close_holes: float = 0.25
    close_smoothness: float = 0.1
    open_handles: int = 4
    window: int = 0
    workers: int = 0
    scheduler: str = "sync"
    cache_dir: str | None = None

    def __post_init__(self):
        super().__post_init__()
        if not self.correct_stretch > 1:
            raise ValueError(f"correct_stretch must be > 1, got {self.correct_stretch!r}")
        for name in ("anchor_spacing", "anchor_gap", "anchor_tolerance", "correct_motion", "alignment_weight",
                     "map_agreement", "color_radius", "color_scale", "rest_weight"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value!r}")
        if self.anchors not in ANCHOR_SOURCES and not str(self.anchors).endswith(".npz"):
            raise ValueError(f"anchors must be one of {', '.join(ANCHOR_SOURCES)} or the path of an .npz "
                             f"anchors file, got {self.anchors!r}")
        for name in ("alignment_settle", "patch_spacing", "anchor_texture", "guide_pull"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be non-negative, got {value!r}")
        if not (np.isfinite(self.relax_tolerance) and 0.0 <= self.relax_tolerance < 1.0):
            raise ValueError(f"relax_tolerance must lie in [0, 1), got {self.relax_tolerance!r}")
        if not 0.0 <= self.alignment_coarse < 1.0:
            raise ValueError(f"alignment_coarse must lie in [0, 1), got {self.alignment_coarse!r}")
        for name in ("alignment_iterations", "relax_sweeps", "registration_iterations", "rest_fit", "open_handles"):
            value = getattr(self, name)
            if int(value) != value or value < 0:
                raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
        for name in ("close_holes", "close_smoothness"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value <= 1):
                raise ValueError(f"{name} must be a fraction in [0, 1], got {value!r}")
        if int(self.relax_walks) != self.relax_walks or self.relax_walks < 1:
            raise ValueError(f"relax_walks must be a positive integer, got {self.relax_walks!r}")
        if int(self.window) != self.window or self.window < 0 or self.window == 1:
            raise ValueError(f"window must be 0 or at least 2 frames, got {self.window!r}")
        if int(self.workers) != self.workers or self.workers < 0:
            raise ValueError(f"workers must be a non-negative integer (0: one per core), got {self.workers!r}")
        # the pair map's own checks (radius, flattening)
        self.pair_options()

    def window_for(self, frames: int) -> int:
        """Frames per window of a run in memory over ``frames`` frames (0: one hierarchy):
        ``window``, or when it is 0, :data:`STREAM_WINDOW` for a sequence of more than
        :data:`WINDOWED_FRAMES` frames that nothing needs whole (``paste``, ``correct``, an
        anchors file).

        >>> Options().window_for(20), Options().window_for(175), Options(window=4).window_for(20)
        (0, 8, 4)
        >>> Options(paste=True).window_for(175)
        0
        """
        whole = self.paste or self.correct or self.anchors not in ANCHOR_SOURCES
        if self.window or frames <= WINDOWED_FRAMES or whole:
            return int(self.window)
        return STREAM_WINDOW

    def merge_workers(self, vertices: int) -> int:
        """The processes the merges of frames of ``vertices`` vertices run in."""
        if self.workers:
            return int(self.workers)
        return (os.cpu_count() or 1) if vertices >= PARALLEL_VERTICES else 1

    def pair_options(self) -> PairOptions:
        """The :class:`PairOptions` of each merge's pair map."""
        return PairOptions(
            crossparam=CrossParamOptions(max_radius=self.max_radius, flattening=self.flattening,
                                         centre_spacing=self.patch_spacing),
            relax=RelaxOptions(sweeps=self.relax_sweeps, walks=self.relax_walks, tolerance=self.relax_tolerance,
                               seed=self.seed),
        )
