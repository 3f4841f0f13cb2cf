"""Method ``garment`` (issue 54; Popa's thesis, chapters 3-4 and Appendix B): markerless
garment capture.

``fourd reconstruct FRAMES/ --method garment [--set photo=pattern.png]``: the garment's openings
tracked as ellipses, a template (inflated from a photo of the garment laid flat, or the first
frame's own surface with its holes filled) fitted onto every frame, the regions no camera sees
completed by the template (:mod:`.pipeline`). Its parts:

- :mod:`.ellipse`: ellipses in space fitted to boundary points, RANSAC candidates near a
  reference ellipse, pruning by location, orientation and size, support (Appendix B.1);
- :mod:`.boundary_tracking`: a garment's boundaries followed through the frames, skipped
  frames interpolated, smoothed in time, and the off-surface anchors (3.6.1, B.1-B.2);
- :mod:`.template`: the template from a photo of the garment laid out flat: silhouette, 2D
  triangulation, front and back sewn along the outline but the openings, inflation that
  opposes stretch and compression (3.7, equations 3.2-3.3);
- :mod:`.fit`: the template fitted onto a frame as rigidly as possible, its openings pulled
  onto the frame's (in place of the thesis' base-mesh parameterisation, 3.6.2, which
  :mod:`.base_mesh` builds but the pipeline does not use: measured in
  ``experiments/garment_base_mesh.py``);
- :mod:`.base_mesh`: the base-mesh parameterisation (3.6.2; its function ``base_mesh`` is
  not re-exported here, where the name is the module's): each opening closed by a cone at
  its anchor, the surface cut into one chart per facet of the anchors' tetrahedron, each chart
  mapped onto its facet (mean-value map, stretch-minimising reweighting, vertices sliding
  across the charts' borders), and points carried between surfaces through the base;
- :mod:`.base_holes`: the holes of that closed surface re-triangulated on the base (Delaunay
  flips) and re-projected by the membrane with the base embedding's mean-value weights, in
  turn with the parameterisation (3.6.2);
- :mod:`.fold_edges`: folds found in a video frame as pairs of parallel, oppositely oriented
  edges flanking a bright ridge or a dark valley (4.3.1, 4.4);
- :mod:`.wrinkle_anchors`: per frame the best views, their fold edges projected onto the
  garment as anchor triangles, and each anchor's rotation (4.4, 4.5.1);
- :mod:`.wrinkling`: the space-time deformation that puts those folds into the garment:
  rotations blended over space and time, vertex positioning, stretch reduction (4.5).

The garment scenes (``tshirt``, ``dress``, with the photo) are in :mod:`fourd.synth.garments`;
the C1 membrane of 3.6.2 is :mod:`fourd.geometry.hole_filling`.
"""

from fourd.methods.garment.base_holes import ClosedOnBase, reparameterize_holes
from fourd.methods.garment.base_mesh import (
    BaseMesh,
    BaseParameterization,
    closed_surface,
    map_through_base,
    parameterize_onto_base,
    vertex_base_coordinates,
)
from fourd.methods.garment.boundary_tracking import (
    BoundaryTrack,
    TrackingOptions,
    initial_ellipses,
    loop_ellipse,
    read_keyframes,
    track_boundary,
    turned_outward,
)
from fourd.methods.garment.ellipse import (
    Ellipse,
    EllipseBatch,
    fit_ellipse,
    fit_ellipses,
    point_distances,
    prune,
    ransac_candidates,
    support,
)
from fourd.methods.garment.fit import FitOptions, align_template, fit_template
from fourd.methods.garment.fold_edges import (
    FoldEdge,
    FoldEdgeOptions,
    FoldPair,
    fold_edges,
    trace_edges,
)
from fourd.methods.garment.options import COMMON_OPTIONS, MIN_FRAMES, RESULT, Options
from fourd.methods.garment.pipeline import reconstruct
from fourd.methods.garment.template import (
    Template,
    TemplateOptions,
    edge_strain,
    inflate,
    outline_from_photo,
    sew_front_and_back,
    template_from_pattern,
    template_from_photo,
    triangulate_outline,
)
from fourd.methods.garment.wrinkle_anchors import (
    AnchorOptions,
    FrameAnchors,
    frame_anchors,
    rotation_between,
)
from fourd.methods.garment.wrinkling import (
    WrinkleOptions,
    WrinkleResult,
    hold_to_data,
    position_vertices,
    spacetime_rotations,
    triangle_stretch,
    wrinkle,
)

__all__ = [
    "BaseMesh",
    "BaseParameterization",
    "ClosedOnBase",
    "COMMON_OPTIONS",
    "MIN_FRAMES",
    "RESULT",
    "FitOptions",
    "Options",
    "align_template",
    "fit_template",
    "reconstruct",
    "BoundaryTrack",
    "Ellipse",
    "EllipseBatch",
    "FoldEdge",
    "FoldEdgeOptions",
    "FoldPair",
    "Template",
    "TemplateOptions",
    "TrackingOptions",
    "edge_strain",
    "inflate",
    "outline_from_photo",
    "sew_front_and_back",
    "template_from_pattern",
    "template_from_photo",
    "triangulate_outline",
    "fit_ellipse",
    "fit_ellipses",
    "fold_edges",
    "initial_ellipses",
    "loop_ellipse",
    "point_distances",
    "prune",
    "ransac_candidates",
    "support",
    "trace_edges",
    "track_boundary",
    "turned_outward",
    "read_keyframes",
    "AnchorOptions",
    "FrameAnchors",
    "WrinkleOptions",
    "WrinkleResult",
    "frame_anchors",
    "hold_to_data",
    "position_vertices",
    "rotation_between",
    "spacetime_rotations",
    "triangle_stretch",
    "wrinkle",
    "closed_surface",
    "map_through_base",
    "parameterize_onto_base",
    "reparameterize_holes",
    "vertex_base_coordinates",
]
