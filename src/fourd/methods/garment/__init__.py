"""Method ``garment`` (issue 54; Popa's thesis, chapters 3-4 and Appendix B): markerless
garment capture and data-driven dynamic wrinkles.

**Under construction**: the method is not registered yet. What is here, tested on its own:

- :mod:`.ellipse`: ellipses in space fitted to boundary points, RANSAC candidates near a
  reference ellipse, pruning by location, orientation and size, support (Appendix B.1);
- :mod:`.boundary_tracking`: a garment's boundaries followed through the frames, skipped
  frames interpolated, smoothed in time, and the off-surface anchors (3.6.1, B.1-B.2);
- :mod:`.fold_edges`: folds found in a video frame as pairs of parallel, oppositely oriented
  edges flanking a bright ridge or a dark valley (4.3.1, 4.4);
- :mod:`.template`: the template from a photo of the garment laid out flat: silhouette, 2D
  triangulation, front and back sewn along the outline but the openings, inflation that
  opposes stretch and compression (3.7, equations 3.2-3.3).

The garment scenes (``tshirt``, ``dress``, with the photo) are in :mod:`fourd.synth.garments`.
Still to come: the base mesh parameterisation (3.6.2), compatible remeshing and completion
(3.7), the best views per frame and the space-time deformation that wrinkles the garment
(4.4-4.5), and the method module itself.
"""

from fourd.methods.garment.boundary_tracking import (
    BoundaryTrack,
    TrackingOptions,
    initial_ellipses,
    track_boundary,
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
from fourd.methods.garment.fold_edges import (
    FoldEdge,
    FoldEdgeOptions,
    FoldPair,
    fold_edges,
    trace_edges,
)
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

__all__ = [
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
    "point_distances",
    "prune",
    "ransac_candidates",
    "support",
    "trace_edges",
    "track_boundary",
]
