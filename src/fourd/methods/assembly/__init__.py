"""The assembly method (issue 51; Popa's thesis, chapter 5): a consistent animated mesh
assembled from per-frame meshes by pairwise cross-parameterisation in a binary hierarchy
(``fourd reconstruct MESHES/ --method assembly``).

Frames that are meshes are used as they are; point clouds are meshed per frame first
(:mod:`fourd.geometry.frame_surface`). The parts, each tested on its own:

- :mod:`.anchors`: sparse source-to-target correspondences, the forward-backward check and
  spreading to a uniform density (section 5.4.1);
- :mod:`.alignment`: anchors from geometry (a coarse non-rigid alignment, then closest
  points), every merge's;
- :mod:`.guides`: anchors from the capture's video (optical flow, 5.4.1) or the user's file,
  which pull that alignment and join its anchors;
- :mod:`.patches`: matching disk-shaped patches grown around anchors (5.4.2);
- :mod:`.crossparam`: the local patch cross-parameterisation, each patch pair flattened
  (ABF++ or LSCM, :mod:`fourd.geometry.flattening`), aligned by its anchors and the most
  central patch chosen per vertex (5.4.2);
- :mod:`.relax`: the local relaxation of that map, its Laplacian coordinates kept by walks
  over the target, flipped triangles fixed (5.4.3);
- :mod:`.registration` and :mod:`.refine`: the source registered in the target's frame by its
  Laplacian coordinates, and anchors added where it lands on the target (5.4.4);
- :mod:`.pair`: those steps chained, one source mesh mapped onto one target mesh;
- :mod:`.hierarchy`: the hierarchical assembly (5.3) and the propagation of each merge through
  the right sub-sequence, unmapped vertices placed by Laplacian registration (5.6);
- :mod:`.completion`: geometry only the later frame has glued into the union mesh along a
  zipped seam, placed in the earlier frames by Laplacian coordinates (5.6, second half);
- :mod:`.method`: the pipeline (``reconstruct``); :mod:`.options` its ``Options``;
- the holes no frame fills are closed at the end by the membrane of 3.6.2, and the first
  frame's small handles cut out and closed the same way
  (:func:`fourd.geometry.hole_closing.close_small_holes`);
- :mod:`.stream`: the same over a whole capture a window of frames at a time, written frame by
  frame (``reconstruct_streamed``, ``fourd reconstruct --stream``; issue 56).

- :mod:`.analysis`: the pair map checked against the gradual change assumption (5.5),
  inconsistent vertices flagged and clustered; the method's ``correct`` option tries the
  source's geometry, then the target's, in each region's place (:mod:`.hierarchy`).
"""

from fourd.methods.assembly.alignment import Alignment, geometric_anchors
from fourd.methods.assembly.analysis import (
    Analysis,
    edge_ratios,
    inconsistent_regions,
    passes_stretch_test,
)
from fourd.methods.assembly.anchors import (
    Anchors,
    anchors_at_vertices,
    consistent_anchors,
    returned_points,
    spread_anchors,
)
from fourd.methods.assembly.completion import Paste, paste_target_only, place_pasted, zip_strip
from fourd.methods.assembly.crossparam import (
    CrossParameterization,
    PatchMap,
    cross_parameterize,
    map_patch,
)
from fourd.methods.assembly.hierarchy import (
    Block,
    MergeMap,
    MergeReport,
    assemble,
    join_blocks,
    map_pair,
    merge_blocks,
    merge_tree,
)
from fourd.methods.assembly.method import (
    COMMON_OPTIONS,
    MIN_FRAMES,
    RESULT,
    AssemblyDiagnostics,
    reconstruct,
    reconstruct_with_diagnostics,
)
from fourd.methods.assembly.options import (
    STREAM_WINDOW,
    CrossParamOptions,
    Options,
    PairOptions,
    RefineOptions,
    RelaxOptions,
)
from fourd.methods.assembly.pair import PairMap, cross_parameterize_pair
from fourd.methods.assembly.patches import GrownPatches, Patch, PatchPair, grow_patches
from fourd.methods.assembly.refine import Refinement, refine_anchors
from fourd.methods.assembly.registration import register_by_laplacian
from fourd.methods.assembly.relax import RelaxedMap, flipped_triangles, mapped_points, relax_map
from fourd.methods.assembly.stream import StreamSummary, reconstruct_streamed

__all__ = [
    "COMMON_OPTIONS",
    "MIN_FRAMES",
    "RESULT",
    "STREAM_WINDOW",
    "StreamSummary",
    "merge_tree",
    "reconstruct_streamed",
    "Alignment",
    "Analysis",
    "edge_ratios",
    "inconsistent_regions",
    "passes_stretch_test",
    "Anchors",
    "AssemblyDiagnostics",
    "Block",
    "Paste",
    "paste_target_only",
    "place_pasted",
    "zip_strip",
    "MergeMap",
    "MergeReport",
    "Options",
    "assemble",
    "geometric_anchors",
    "join_blocks",
    "map_pair",
    "merge_blocks",
    "reconstruct",
    "reconstruct_with_diagnostics",
    "CrossParamOptions",
    "CrossParameterization",
    "GrownPatches",
    "Patch",
    "PatchMap",
    "PairMap",
    "PairOptions",
    "PatchPair",
    "RefineOptions",
    "Refinement",
    "RelaxOptions",
    "RelaxedMap",
    "anchors_at_vertices",
    "consistent_anchors",
    "cross_parameterize",
    "cross_parameterize_pair",
    "flipped_triangles",
    "grow_patches",
    "map_patch",
    "refine_anchors",
    "register_by_laplacian",
    "mapped_points",
    "relax_map",
    "returned_points",
    "spread_anchors",
]
