"""Options of the ``flow`` method and its fixed constants."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from fourd.animation import MeshSequence

MIN_FRAMES = 2
RESULT = MeshSequence
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
        32 by default here: on crane, bench at 68be547 / 7ca8ce0, medians of 3, 0.97 s/frame
        with Chamfer / completeness-95 0.0026 / 0.0067 at 32 and 3.5-3.8 s/frame (2.3 GB) with
        0.0030 / 0.0069 at 64; at 7206043, splitting-blob 0.0019 / 0.0031 at 32 and 0.0091 /
        0.0134 at 64: thick objects came out hollow there, as the fit's interior turned
        slightly positive, so ``deep_inside`` labelled nothing (with ``fit_offset`` and
        ``deep_inside`` 2 at 61f29dd: 0.0030 / 0.0056), and the motion outruns one cell per slice; 6 IRLS
        iterations instead of 3 gave 0.0099, and labelling where the fit is below 0.2 with
        ``time_substeps=0`` 0.0042 / 0.0070 at twice the time).
    neighbourhood : int
        Temporally adjacent cells a cell's material may flow to: 27 (the paper's Figure 2) or
        7 (the cell and its face neighbours; faster, motion only along axes per step).
    time_substeps : int
        Solution slices per frame interval (1: one slice per frame; 2: one empty slice
        between frames, the paper's solution grid finer than the data, halving the speed bound;
        0: automatic, see ``motion_limit``). Material moves at most one cell per slice, so
        faster motion cannot be followed: conserving mass then pulls material out of the
        interior (``squash-ball``, whose poles move up to 1.5 cells per frame at resolution 32:
        with 1 slice per frame, cavities in 7 of 20 frames, filled by ``cavities=False``; bench
        at 5cae82f, Chamfer / completeness-95 / volume change 0.0047 / 0.0130 / 15% at 8.6
        s/frame; with ``time_substeps=0``, which picks 2, no cavities and 0.0041 / 0.0109 / 8%
        at 18.4 s/frame). Cavities in the output are logged as a warning. Not automatic by
        default: crane's leg moves up to 5.8 cells per frame, so the rule below picks 3 for
        it, but with 2 it measured no better (Chamfer / completeness-95 0.0035 / 0.0072
        against 0.0034 / 0.0069) at twice the cost.
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
        ``"zero"`` (the paper: ``F_r = sum x^2 + sum v^2``) or ``"previous"`` (``sum (x -
        x_0)^2 + sum v^2`` with ``x_0`` each solve's starting values: the implicit fit's
        inside indicator, then the previous iterate; the same matrix, so the same
        conditioning). Pulling towards zero empties large regions no camera sees: over a
        big unseen part the continuity term holds the free cells only weakly, and the
        regulariser lowers them below 0.5 (a still ball scanned by the standard cameras,
        which look down on it: its unseen lower half comes out at interior values about
        0.45 and each frame's enclosed volume at 0.61 of the truth; 0.985 with
        ``"previous"``). But on concave parts no camera sees, pulling towards zero is what
        keeps the surface off them. Measured with the standard scans (20k samples; Chamfer /
        completeness-95, zero -> previous): dfaust-hopping 0.0040 / 0.0114 -> 0.0043 /
        0.0133 (accuracy-95 0.0096 -> 0.0131: material between the legs), crane 0.0034 /
        0.0072 both, splitting-blob 0.0027 / 0.0049 -> 0.0026 / 0.0048, squash-ball 0.0058
        / 0.0133 -> 0.0052 / 0.0147 (volume change 15% -> 12%). Default ``"zero"``; use
        ``"previous"`` for objects with a large unseen convex side (resting on a floor,
        seen from above). A lower ``regularization`` (1e-4) instead fills the still ball
        too but leaves MINRES unconverged within ``max_outer`` (residual 0.35 on
        squash-ball), and the clamping then fixes wrong values (squash-ball Chamfer
        0.0127).
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
        Upper bound on IRLS iterations. With the standard scans the loop reaches it before
        ``stop_fraction`` (about 40% of the hull decided after 12 iterations), and the frames
        after the postprocessing no longer change past 3 iterations (bench scans, 20k samples,
        Chamfer / completeness-95 at 6 and at 3 iterations: crane 0.0034 / 0.0069 both;
        dfaust-hopping 0.0040 / 0.0111 and 0.0040 / 0.0114; splitting-blob 0.0028 / 0.0050
        and 0.0027 / 0.0050, right part count in every frame), so the default is 3 (12, then
        6 before); the flow stage costs about proportionally less. 2 at resolution 64 (``exp``
        runs at 87dff7d's parent, 20k samples, Chamfer / completeness-95 / s/frame, 3 -> 2):
        squash-ball 0.0040 / 0.0077 / 7.64 -> 0.0040 / 0.0080 / 5.96, crane 0.0029 / 0.0057 /
        1.98 -> 0.0029 / 0.0058 / 1.59, splitting-blob 0.0036 / 0.0064 / 1.97 -> 0.0036 /
        0.0062 / 1.66, but dfaust-hopping 0.0038 / 0.0121 / 2.71 -> 0.0039 / 0.0124 / 2.10
        (its bench completeness-95 at 3, 0.0117, is near issue 5's bound 0.012). No stopping
        rule told the scenes apart: the fraction of free cells whose value crosses 1/2 in a
        solve falls alike on both (squash-ball 23, 24, 11, 6%; dfaust-hopping 11, 11, 5, 3%).
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
        IRLS iteration; raise it with ``inner="cg-amg"`` for the paper's tolerances). 60
        measured the same figures, 20-30% slower (bench at 2541e13, single runs, Chamfer /
        completeness-95 at 60 and 40: crane 0.0026 / 0.0066 both, dfaust-hopping 0.0031 /
        0.0111 and 0.0031 / 0.0112, squash-ball 0.0040 / 0.0133 and 0.0041 / 0.0134); 30 gave
        squash-ball 0.0054 / 0.0110.
    later_outer : int
        MINRES iteration limit of the IRLS solves after the first, which start from the
        previous solve's values and flows (0, the default: ``max_outer``). 10 makes the
        method 20-35% faster, but the truncated later solves conserve mass less well. The
        surfaces hardly changed (``exp`` runs, 20k samples, Chamfer /
        completeness-95, 40 -> 10 later steps): at 32 crane 0.0032 / 0.0062 -> 0.0033 /
        0.0062 (0.81 -> 0.64 s/frame), squash-ball 0.0036 / 0.0066 -> 0.0033 / 0.0062
        (2.56 -> 1.90), dfaust-hopping 0.0040 / 0.0114 -> 0.0041 / 0.0116 (1.04 -> 0.84),
        splitting-blob 0.0027 / 0.0050 -> 0.0025 / 0.0050 (0.79 -> 0.62); at 64 crane
        0.0029 / 0.0057 -> 0.0030 / 0.0060 (2.96 -> 2.26), squash-ball 0.0040 / 0.0079 ->
        0.0039 / 0.0074 (15.7 -> 11.5 s/frame; its later solves 79 and 72 s -> 35 s each,
        of which about 25 s are the set-up). Bench at 09ba8d4 (60k samples, single runs,
        Chamfer / completeness-95 / mass conservation error / s/frame, 40 -> 10 later
        steps): at 32 crane 0.0025 / 0.0055 / 1.7% / 0.84 -> 0.0025 / 0.0054 / 2.8% / 0.68,
        dfaust-hopping 0.0031 / 0.0110 / 0.2% / 1.11 -> 0.0031 / 0.0112 / 1.9% / 0.84,
        squash-ball 0.0025 / 0.0047 / 1.2% / 2.54 -> 0.0021 / 0.0041 / 4.3% / 1.84,
        splitting-blob 0.0018 / 0.0032 / 1.0% / 0.79 -> 0.0017 / 0.0034 / 4.2% / 0.63; at 64
        crane 0.0021 / 0.0044 / 4.4% / 3.21 -> 0.0022 / 0.0050 / 5.5% / 2.39,
        dfaust-hopping 0.0029 / 0.0116 / 0.6% / 4.42 -> 0.0030 / 0.0125 / 2.6% / 3.16 (over
        issue 5's completeness bound 0.012), squash-ball 0.0029 / 0.0069 / 0.9% / 15.4 ->
        0.0028 / 0.0063 / 1.0% / 11.4 (peak 3964 -> 4050 MiB), splitting-blob 0.0027 /
        0.0055 / 6.2% / 3.15 -> 0.0023 / 0.0036 / 9.3% / 2.36. With 20 later steps, ``exp``
        at 32: squash-ball's mass error 3.1%, dfaust-hopping's 0.9%. The paper reports
        under 2%, so the default stays. One IRLS iteration instead of three gave the same
        surfaces at 32 too (squash-ball 0.0032 / 0.0062 at 1.30 s/frame), but without any
        reweighting the paper's sub-linear continuity norm would be gone.
    reuse_interpolation : bool
        With ``inner="amg"``, IRLS iterations after the first keep the previous V-cycle's
        AMG interpolation, restricted to the unknowns still free, and only recompute the
        coarse matrices (half the set-up; the same MINRES residual on the captured crane
        systems, see :func:`.saddle.solve_saddle`). False: a new set-up every iteration.
    reuse_coarse : bool
        With ``reuse_interpolation`` (the default, true): keep the previous solve's coarse
        matrices too (restricted to the unknowns still free, compacted in place), so that the
        later solves never form ``A + B^T B`` nor its Galerkin products; only the finest
        level's sweeps see the new system (see :func:`.saddle.solve_saddle`
        ``reuse_coarse``). The same residual after 10 steps (crane at 32: 3.3e-2 -> 3.4e-2;
        squash-ball 2.5e-2 both) and the same figures, the later solves' set-up down to a few
        restrictions. Bench at 63fe479 (60k samples, single runs): squash-ball at 64 15.2 ->
        13.6 s/frame, Chamfer / completeness-95 0.0029 / 0.0069 and mass conservation error
        0.9% both, peak 3761 -> 3707 MiB. ``exp`` at 32: squash-ball flow stage 41.4 -> 36.3
        s, mass conservation error 1.19% -> 1.30%, dfaust-hopping 13.0 -> 11.5 s, 0.22% ->
        0.24%. It was off until the next system's assembly and the restriction got lighter
        (squash-ball at 64 peaked at 4.8 GiB with it, 3.8 without, before e09226b..63fe479).
    interpolation_entries : int
        With ``inner="amg"``: keep only this many largest entries per row of the V-cycle's
        AMG interpolations (0: all, the default). One entry keeps the coarse matrices
        sparse, so each MINRES step is cheaper, at the same residual on the first solves,
        but the solutions conserve mass less well. Measured on squash-ball (``exp`` runs,
        20k samples; Chamfer / completeness-95, flow stage) at resolution 64: all entries
        0.0040 / 0.0079 in 300 s, one 0.0044 / 0.0086 in 193 s, one with ``max_outer=50``
        0.0040 / 0.0083 in 213 s, two 0.0043 / 0.0084 in 214 s; at 32: all 0.0036 / 0.0066
        in 50 s, one 0.0042 / 0.0082 in 33 s, one with ``max_outer=50`` 0.0038 / 0.0071 in
        38 s. Also less memory (squash-ball at 64, first solve: 4.0 -> 3.2 GB).
    coarse_drop : float
        With ``inner="amg"``: drop the off-diagonal entries ``|a_ij| < coarse_drop
        sqrt(a_ii a_jj)`` of the V-cycle's coarse matrices, lumped onto their diagonals (0:
        none, the default; :func:`.sparse.drop_weak_entries`). The first coarse level of
        squash-ball at 64 has 80 nonzeros per row, more work per V-cycle than the finest
        level; 0.05 keeps 16M of its 87M and the first solve took 77.8 s instead of 95.8 at
        about the same residual (1.82e-2 against 1.76e-2, the captured system). But like
        one interpolation entry per row, it keeps the residual and loses output quality:
        bench at 2b70b99 (Chamfer / completeness-95 / mass conservation error / s/frame,
        0 -> 0.05): at 64 squash-ball 0.0029 / 0.0069 / 0.9% / 13.6 -> 0.0034 / 0.0080 /
        1.0% / 10.7 (over issue 5's Chamfer bound; peak 3699 -> 3572 MiB), dfaust-hopping
        0.0029 / 0.0116 / 0.7% / 3.73 -> 0.0030 / 0.0123 / 0.7% / 3.05 (over its
        completeness bound), crane 0.0021 / 0.0044 / 2.79 -> 0.0021 / 0.0045 / 2.24,
        splitting-blob 0.0027 / 0.0054 / 2.86 -> 0.0027 / 0.0052 / 2.26; at 32 squash-ball
        0.0026 / 0.0047 / 1.3% -> 0.0037 / 0.0101 / 1.8%, the other three the same surfaces,
        5-10% faster. So it is off by default.
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
        normal (see :mod:`.fit`; 0: none, as the paper). None: 1 at ``resolution`` 48 and
        above, none below. A thick object is many cells thick there and its fit's interior
        came out positive, so nothing labelled it and the flow left it hollow. Measured
        (``exp`` runs, 20k samples, Chamfer / completeness-95, 0 -> 1): at 64,
        ``splitting-blob`` 0.0098 / 0.0153 -> 0.0073 / 0.0130, ``squash-ball`` (bench 0.0085
        / 0.0271) -> 0.0072 / 0.0185, ``touching-spheres`` 0.0101 / 0.0297 -> 0.0058 /
        0.0174, ``crane`` 0.0042 / 0.0080 -> 0.0039 / 0.0072, ``dfaust-hopping`` 0.0043 /
        0.0129 -> 0.0043 / 0.0128 (bench at 4d3515f, 60k samples, one run: ``splitting-blob``
        0.0090 / 0.0149 -> 0.0065 / 0.0125, ``crane`` 0.0033 / 0.0074 -> 0.0030 / 0.0065,
        ``dfaust-hopping`` 0.0033 / 0.0124 -> 0.0033 / 0.0123, the same s/frame); at 48,
        ``touching-spheres`` 0.0052 / 0.0181 -> 0.0045 / 0.0110. At 32 the fit's interior is already mostly negative and a cell is coarse
        next to the gaps between parts: ``touching-spheres`` 0.0039 / 0.0085 -> 0.0052 /
        0.0159, ``waving-sheet`` 0.0109 / 0.0128 -> 0.0145 / 0.0072 (with offset points out
        along the normal too, at +1/2: 0.0071 / 0.0223 and 0.0146 / 0.0072).
    deep_inside : float or None
        Cells where the implicit fit is negative and that lie at least this many flow cells
        from every carved and every data cell are labelled inside too (0: only the fit's
        local minima, as the paper; None: 4 below ``resolution`` 48, 2 from 48 on, see
        below). A deviation for thick objects: the paper runs IRLS until 90-95% of the
        cells are decided, this method stops after ``max_iterations``,
        and the interior of a thick object far from the few seeds stays undecided, near 0
        where no data holds it up (``rigid-turn``, a ball about 15 cells in radius: the
        local minima are no cell, the seeds about 300 per slice, and a pit from the unseen
        underside reached about half way to the centre, 17% of the volume missing). Measured (``exp``
        runs, 20k samples, Chamfer / completeness-95 / volume change, 0 against 4):
        ``rigid-turn`` 0.0183 / 0.0339 / 7.2% -> 0.0076 / 0.0299 / 1.4% (2 and 3 cells: 0.0079
        and 0.0082), ``squash-ball`` 0.0054 / 0.0137 -> 0.0052 / 0.0152, ``touching-spheres``
        0.0039 / 0.0086 -> 0.0040 / 0.0086; the thinner scenes at resolution 32 have almost no
        such cells (the same figures), and ``crane`` and ``dfaust-hopping`` at resolution 64
        are within 0.0001. At 64 (with ``fit_offset``) the band of 4 cells left free under
        the data is twice as many cells as at 32, and the three capped IRLS iterations left a
        pit from ``splitting-blob``'s unseen side (``exp``, frame 0, volume / mean distance to
        the truth: 0.79 / 0.0178 of the diagonal with 4 cells, 0.97 / 0.0029 with 2).
        Bench at 4d3515f (60k samples, single runs), Chamfer / completeness-95 at 64, 4 -> 2
        cells: ``splitting-blob`` 0.0065 / 0.0125 -> 0.0030 / 0.0056, ``squash-ball``
        0.0062 / 0.0182 -> 0.0036 / 0.0075 (volume change 1.1% -> 1.4%),
        ``touching-spheres`` 0.0047 / 0.0172 -> 0.0036 / 0.0118, ``dfaust-hopping`` 0.0033 /
        0.0123 -> 0.0033 / 0.0124, ``crane`` 0.0030 / 0.0065 -> 0.0032 / 0.0066 (3 cells:
        crane 0.0031 / 0.0065, splitting-blob 0.0031 / 0.0060). At 48 (rigid-turn, 3
        frames) the two together keep 0.985 of the ball's volume, 0.26 without.
    still_interior : int or None
        Material stays in cells fixed inside at least this many cells deep (every cell within
        that many cells of them, in their slice, fixed inside too) and fixed inside in the
        next slice as well: their flows to other cells are dropped, so are flows into them
        from other cells, and their flow to themselves, which must then be 1, is a constant
        instead of an unknown with its two constraints (:func:`.system.still_interior`; 0:
        flows everywhere, the paper; None, the default: 1 from ``resolution`` 48 on, 0
        below, where thick interiors are a few cells). Inside a solid every cell is full
        whatever the flows between its cells, so a thick object's interior only costs
        unknowns: a deviation for speed. A still interior cannot carry a translating solid
        along, so where a thick object translates its boundary layers lag (a block moving
        one cell per slice: free values off by up to 0.07, ``tests/methods/test_flow.py``).
        Bench at 29c40b2 (resolution 64, single runs one after the other on the 2-core
        machine, the flows to themselves still unknowns; Chamfer / completeness-95 /
        s/frame / peak MiB, 0 -> 1): squash-ball 0.0029 / 0.0067 / 7.59 / 3681 -> 0.0028 /
        0.0066 / 5.66 / 2847 (38-58% of the flows dropped in its three solves; mass
        conservation error 0.9% -> 1.6%, volume change 0.4% -> 0.9%), dfaust-hopping 0.0029
        / 0.0117 / 2.78 -> 0.0029 / 0.0116 / 2.57, splitting-blob 0.0027 / 0.0056 / 2.04 ->
        0.0026 / 0.0058 / 1.79, crane 0.0021 / 0.0044 / 2.00 -> 0.0021 / 0.0042 / 1.99; but
        touching-spheres, whose balls move more than a cell per slice towards each other,
        0.0036 / 0.0112 / 3.29 -> 0.0039 / 0.0128 / 3.03. ``exp`` runs (20k samples): rigid-turn
        at 64 0.0063 / 0.0257 / 20.1 -> 0.0062 / 0.0235 / 12.7 s/frame; squash-ball with the
        flows to themselves as constants 5.25 -> 4.61 s/frame in the same hour (0.0039 /
        0.0076 / 1.6% -> 0.0039 / 0.0077 / 1.4% mass conservation error). Keeping the deep
        cells' flows along their connected piece's centroid motion too kept touching-spheres
        at 0.0049 / 0.0126 (``exp``, 20k samples; 0.0047 / 0.0116 with every flow) and
        squash-ball, whose labelled pieces' centroids wander, at 6.86 s/frame, so it was
        dropped. At the default resolution 32 (bench at b6746ef, single runs, 0 -> 1): 10-15%
        faster, surfaces mixed (rigid-turn 0.0066 / 0.0316 / 3.59 -> 0.0069 / 0.0291 / 3.11,
        squash-ball 0.0025 / 0.0046 / 1.76 -> 0.0026 / 0.0048 / 1.61, touching-spheres 0.0025
        / 0.0069 / 1.06 -> 0.0024 / 0.0061 / 1.01), so below 48 it stays off.
    outlier_factor : float
        Statistical outlier filter: drop points whose 8th-neighbour distance exceeds this
        multiple of the median.
    refine : int
        Refinement factor of the postprocessing band (fine spacing ``h / refine``).
    band : float
        Half-width of the refined band around the flow surface, in flow cells.
    smoothness : float
        Weight of the Laplace term of the postprocessing (per 4D edge, against weight 1 of
        the data targets). Its edges include time, so a strong term blends each frame's
        surface with its neighbours' and smooths the zero level off the data. Measured with
        the standard scans (20k samples; Chamfer / completeness-95): 0.5 -> 0.1 takes crane
        from 0.0054 / 0.0176 to 0.0034 / 0.0069, dfaust-hopping from 0.0048 / 0.0196 to
        0.0040 / 0.0111, splitting-blob from 0.0034 / 0.0077 to 0.0028 / 0.0050; squash-ball
        (6 frames) 0.0107 / 0.039 -> 0.0100 / 0.019 but its accuracy drops (0.012 -> 0.015).
        0.02 is no better. Default 0.1 (0.5 before; those figures were with ``time_smoothness``
        1).
    time_smoothness : float
        Weight of the Laplace term's temporal edges between two slices that both have data,
        relative to its spatial edges (the paper's 4D Laplace solve: 1). Edges touching a
        slice without data (a missing frame, a sub-step slice) keep weight 1, so such slices
        are still filled from their neighbours. Where a part moves by more than its thickness
        per frame, the temporal edges pull its data nodes towards the outside values of the
        neighbouring frames, and the part is lost: ``crane`` at resolution 64, frame 15, had
        the field at +0.9 cells on the arm's data points and the mesh ended at the elbows
        (``exp`` runs, 20k samples, Chamfer / completeness-95, 1 -> 0): ``crane`` at 64 0.0040
        / 0.0072 -> 0.0030 / 0.0054 (0.25: 0.0031 / 0.0055); at 32 ``crane`` 0.0034 / 0.0072
        -> 0.0032 / 0.0062, ``horse-gallop`` 0.0092 / 0.0923 -> 0.0071 / 0.0538 (0.1: 0.0074
        / 0.0625), ``touching-spheres`` 0.0039 / 0.0085 -> 0.0037 / 0.0079, ``squash-ball``
        0.0038 / 0.0068 -> 0.0036 / 0.0066, ``dfaust-hopping``, ``splitting-blob`` and
        ``bending-arm`` within 0.0001 / 0.0002; worse: ``waving-sheet`` 0.0109 / 0.0128 ->
        0.0115 / 0.0115 and ``rigid-turn`` completeness-95 0.0319 -> 0.0324. Default 0.
    min_component : float
        Closed components with volume below this fraction of the frame's largest are dropped.
    hull_trim : bool
        Before the postprocessing, empty the cells outside a tighter visual hull (the
        sampling's gaps and a one-pixel rim filled instead of a three-pixel rim, see
        :func:`~.grid.carve_visual_hull`). The flow itself keeps the wider hull (solving with
        the tighter one pulls material out of the interior where the motion is fast), but
        where it parks material in the rim above a grazing view, the output would bulge.
    cavities : bool
        Keep closed cavities inside the solid (inner surfaces, negative enclosed volume). Off
        by default: no scanner outside the object sees one, so a cavity is the flow's doing.
        Where the motion is faster than the flow's one cell per time step, conserving mass
        pulls material out of the interior and leaves a pocket there (``squash-ball`` with
        one slice per frame: inner surfaces in 7 of 20 frames at 5cae82f; before the hull
        trim, 10 of 20, the largest 11% of the solid's volume).
    mass_levels : bool or "auto"
        For incompressible objects: move the unobserved parts of each frame's mesh along
        their normals so that its enclosed volume follows the flow's conserved mass
        (:func:`mass_meshes`). A deviation from the paper, which contours the zero level: the
        flow carries the mass into the parts no scanner sees, but the Laplace solve puts the
        zero level there where the flow's smeared values cross it, so the extracted volume
        does not follow the mass (``squash-ball``, bottom unseen: 12.6% volume change at a
        0.5% mass error, the unseen pole up to 45% of the radius off). Measured on
        ``squash-ball`` at resolution 32 (``exp`` runs, 20k samples; Chamfer /
        completeness-95 / volume change): zero level 0.0054 / 0.0137 / 12.6%, this without
        smoothing 0.0046 / 0.0074 / 1.7% and with it 0.0039 / 0.0076 / 1.7%, the whole
        surface moved by one offset (u = 1) 0.0062 / 0.0114 / 1.8%; bench (5f84121, 60k
        samples): 0.0029 / 0.0066 / 1.7%, and 0.0027 / 0.0047 / 1.4% with
        ``regularize_towards="previous"``. More time slices do not help: with
        ``time_substeps=2`` the flow's mass conservation error rises to 2.4-2.8% (the capped
        MINRES solves) and the volumes, which follow the mass, change by 6.7-7.6% (``exp``,
        60k samples). Always on, it forces a constant volume, and the true volume of
        ``splitting-blob`` and of captured people is not (bench at 4512ce4, Chamfer without /
        with: ``splitting-blob`` 0.0019 / 0.0063, ``dfaust-hopping`` 0.0031 / 0.0040;
        ``crane``, ``bending-arm``, ``touching-spheres``, ``horse-gallop`` and
        ``elephant-gallop`` within 0.0004 either way). ``"auto"`` (the default) tests the
        hypothesis first (:func:`mass_meshes` ``all_or_nothing``): the offsets are applied
        only when no frame asks its unobserved parts to move by more than the object's mean
        radius ``3 V / A`` (first, linear estimate), that is when the parts no scanner saw
        can account for the frames' volume differences. Measured at resolution 32, largest
        offset over the frames against that radius: ``squash-ball`` 3.7 / 10.7 cells = 0.37
        and ``horse-gallop`` 2.7 / 2.9 = 0.87 (applied); ``dfaust-hopping`` 7.8 / 3.3 =
        2.5, ``splitting-blob`` 13.2 / 5.3 = 2.8 and ``crane`` 7.7 / 2.5 = 3.1 (left alone:
        only 2-4% of their surface is unobserved, and the volume of a person or of a
        splitting blob does change). Bench at a66da0d / ae2357b (single runs), Chamfer /
        completeness-95 / volume change, contoured -> auto: ``squash-ball`` 0.0042 / 0.0150
        / 12% -> 0.0026 / 0.0048 / 0.9%, ``touching-spheres`` 0.0029 / 0.0080 -> 0.0027 /
        0.0075, ``elephant-gallop`` 0.0069 / 0.0248 -> 0.0065 / 0.0264; worse:
        ``rigid-turn`` 0.0062 / 0.0295 -> 0.0063 / 0.0366 (the smoothing flattens bumps of
        the unseen side that the flow had carried round; at 502a8b7, smoothing in
        proportion to the volume error: ``rigid-turn`` 0.0063 / 0.0317, ``squash-ball``
        0.0027 / 0.0052 / 0.9%, see ``unobserved_smoothing``). The Newton iteration's own
        offsets are no test:
        squash-ball's frame 3 asks 2.6 cells linearly but 6.5 after a step, its offset
        region's volume growing slower than linearly.
    observed_distance : float
        With ``mass_levels``: vertices within this many flow cells of a data point of their
        frame stay; the offset's weight rises to 1 over the next flow cell. Above resolution
        32 the cells of this test are those of resolution 32 (the longest side / 32), so the
        same parts count as observed on a finer grid. With the finer grid's own cells, the
        gaps between scan lines counted as unobserved too (5.0% of ``crane``'s surface and
        6.7% of ``dfaust-hopping``'s at 64, 1.9% and 2.3% at 32), their large area let small
        offsets account for the volume differences, and ``"auto"`` applied the offsets at
        64, where at 32 it did not (``exp`` runs, 20k samples, Chamfer / completeness-95
        applied / not: ``dfaust-hopping`` 0.0043 / 0.0128 / 0.0038 / 0.0120, ``crane`` 0.0030
        / 0.0054 and 0.0029 / 0.0057).
    level_limit : float
        With ``mass_levels``: the largest offset of a frame's unobserved parts, in flow cells
        (``squash-ball`` at resolution 32 needs up to 3.2). Large offsets can make concave
        unseen parts self-intersect.
    unobserved_smoothing : int
        With ``mass_levels``: umbrella smoothing steps of the unobserved parts before the
        offset (``squash-ball``, ``exp``, 20k samples; Chamfer / accuracy-95: 0 steps 0.0046 /
        0.0150, 20 0.0041 / 0.0097, 100 0.0039 / 0.0089, 300 0.0038 / 0.0083 with
        completeness-95 0.0080 against 0.0076 at 100). Steps are per mesh edge, so the
        smoothed distance shrinks with finer meshes (higher ``resolution``). Each frame's
        steps are scaled by how far its volume is off, its first offset in flow cells, at
        most 1 (:func:`mass_meshes`): until then every frame was smoothed fully, and frames
        whose volume the flow got right lost the shape it had carried into their unseen
        parts (``exp``, 20k samples, Chamfer / completeness-95, full -> scaled:
        ``rigid-turn`` 0.0077 / 0.0369 -> 0.0076 / 0.0319 (0.0296 unsmoothed),
        ``elephant-gallop`` 0.0074 / 0.0267 -> 0.0075 / 0.0257, ``crane-still`` 0.0036 /
        0.0071 -> 0.0036 / 0.0069; ``squash-ball`` 0.0037 / 0.0066 -> 0.0038 / 0.0068 and
        ``touching-spheres`` 0.0038 / 0.0083 -> 0.0039 / 0.0085 lose a little; smoothing
        only from half a cell on gave ``rigid-turn`` 0.0296 but ``squash-ball`` 0.0039 /
        0.0071 and ``touching-spheres`` 0.0040 / 0.0089).
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
        object.__setattr__(self, "missing_frames", tuple(int(i) for i in self.missing_frames))
