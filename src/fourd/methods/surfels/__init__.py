"""Method ``surfels``: a graph of oriented particles that move over time, fitted to the data
by a statistical model and assembled frame range by frame range (Wand et al. 2007).

``fourd reconstruct FRAMES/ --method surfels``; :func:`reconstruct` (:mod:`.pipeline`) with
:class:`Options` (:mod:`.options`). The modules:

1. :mod:`.state` -- surfel positions, normals and local rotations over time; the tangent-plane
   and rotation-vector parameterisation of a step (eq. 11, 12);
2. :mod:`.topology` -- the sampling distance ``eps_sampl``, an initial surfel sample and the
   topology graph ``T_S`` (edges within ``eps_top = 2 eps_sampl``);
3. :mod:`.match` (eq. 5), :mod:`.smoothness` (eq. 6-8), :mod:`.motion` (eq. 9, 10) -- the
   energy terms with gradients and Gauss-Newton Hessians (:mod:`.term`), summed by
   :mod:`.energy` (eq. 3);
4. :mod:`.optimizer` -- the optimiser (sparse Gauss-Newton, preconditioned CG);
5. :mod:`.meshing` -- the animated mesh (sec. 3.3): one frame's blended tangent planes
   contoured with border clipping, carried to every frame by the surfels' Gaussian weights;
6. :mod:`.seeds` -- preprocessing (outlier removal, tensor voting with
   :func:`fourd.geometry.tensor_voting.tensor_voting`, oriented normals) and one seed model
   per frame (sec. 3.2);
7. :mod:`.model`, :mod:`.align`, :mod:`.fill`, :mod:`.resample`, :mod:`.assembly` -- the
   iterative model assembly (sec. 3.2): frame ranges merged in a binary scheme by alignment
   (non-rigid ICP both ways, the one with less stretch kept), stitching with the stretch filter, hole filling by region growing in time,
   greedy resampling and global optimisation, then a final global optimisation with
   increased rigidity and acceleration weights;
8. :mod:`.urshape` -- the urshape (sec. 3.2): a data-free frame tied to every frame by the
   rigidity prior; by default fitted to the final trajectories (``Options.urshape``
   ``"rest"``), or optimised with them after the final global optimisation (``"final"``) or
   after every merge's as well (``"merges"``, the paper's schedule; measured in
   benchmarks/METHODS.md);
9. :mod:`.pipeline` -- all of it, and the mesh of :mod:`.meshing`: one frame's mesh carried
   to every frame and to the urshape, which is the result's ``rest``;
10. :mod:`.stream` -- a whole capture window by window (``window``, ``--stream``): each
    window assembled, then merged onto the past's last frames with those held, the first
    frame's mesh carried on; memory bounded by the window.

Beyond the paper (measured in benchmarks/METHODS.md): the alignment pulls towards the right
frame's measured points (not its surfels) and starts from a rigid point-to-plane ICP
(:func:`fourd.geometry.icp.rigid_icp`), whose turn is kept only where the data determine it
and below 30 degrees; a small tangential share of the point distance in the data term
outside the alignment (``tangential``, ``linked_tangential``), which keeps open patches from
shrinking; every frame's mesh fitted along its normals to that frame's points
(``fit_frames``); with the capture's video, anchors tracked by optical flow pull each surfel
along the surface as well (:mod:`.anchors`, ``video_anchors``), and the colours of the points
(or of the video) pull each surfel in the global optimisations to where its first frame's
colours say it is (:mod:`.color_guide`, ``color_guide``). Slow: tens of seconds per
frame at a standard scan, against the issue's 2 s target.

References
----------
Wand, Jenke, Huang, Bokeloh, Guibas, Schilling: Reconstruction of deforming geometry from
time-varying point clouds, SGP 2007 (``001_3fedd1c3a0ac4198.txt``).
"""

from fourd.methods.surfels.anchors import AnchorData, Forward, anchor_term, pair_anchors
from fourd.methods.surfels.color_guide import (
    GuideData,
    GuideSettings,
    color_guides,
    guide_term,
    reference_colors,
)
from fourd.methods.surfels.energy import Energy, Weights, total_energy
from fourd.methods.surfels.match import (
    Data,
    Matches,
    MatchOptions,
    associate,
    frame_data,
    match_term,
)
from fourd.methods.surfels.meshing import (
    Binding,
    FrameMesh,
    MeshingOptions,
    align_to_normals,
    bind_vertices,
    carry,
    carry_by,
    mesh_frame,
    observed_vertices,
    surfel_frames,
    surfel_mesh,
)
from fourd.methods.surfels.motion import accel_term, fit_rotations, rigid_term
from fourd.methods.surfels.optimizer import (
    GaussNewtonOptions,
    Optimization,
    free_unknowns,
    gauss_newton,
    solve_step,
)
from fourd.methods.surfels.options import COMMON_OPTIONS, MIN_FRAMES, RESULT, Options
from fourd.methods.surfels.pipeline import reconstruct
from fourd.methods.surfels.smoothness import laplace_term, smooth_normal_term, smooth_position_term
from fourd.methods.surfels.state import (
    Layout,
    SurfelState,
    layout,
    move,
    retract,
    skew,
    surfel_state,
    tangent_basis,
)
from fourd.methods.surfels.stream import STREAM_WINDOW, reconstruct_streamed
from fourd.methods.surfels.term import Term
from fourd.methods.surfels.topology import (
    Topology,
    build_topology,
    sample_surfels,
    sampling_distance,
)
from fourd.methods.surfels.urshape import Urshape, UrshapeFit, fit_urshape, with_urshape

__all__ = [
    "COMMON_OPTIONS",
    "MIN_FRAMES",
    "Options",
    "RESULT",
    "reconstruct",
    "reconstruct_streamed",
    "STREAM_WINDOW",
    "free_unknowns",
    "AnchorData",
    "Binding",
    "Data",
    "Energy",
    "FrameMesh",
    "Forward",
    "GaussNewtonOptions",
    "GuideData",
    "GuideSettings",
    "Layout",
    "MatchOptions",
    "Matches",
    "MeshingOptions",
    "Optimization",
    "SurfelState",
    "Term",
    "Topology",
    "Urshape",
    "UrshapeFit",
    "Weights",
    "accel_term",
    "anchor_term",
    "color_guides",
    "guide_term",
    "reference_colors",
    "build_topology",
    "associate",
    "bind_vertices",
    "carry",
    "carry_by",
    "align_to_normals",
    "observed_vertices",
    "fit_rotations",
    "fit_urshape",
    "frame_data",
    "gauss_newton",
    "laplace_term",
    "layout",
    "match_term",
    "mesh_frame",
    "move",
    "pair_anchors",
    "retract",
    "rigid_term",
    "sample_surfels",
    "sampling_distance",
    "skew",
    "smooth_normal_term",
    "smooth_position_term",
    "surfel_frames",
    "surfel_mesh",
    "solve_step",
    "surfel_state",
    "tangent_basis",
    "total_energy",
    "with_urshape",
]
