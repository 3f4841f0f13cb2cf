"""Method ``auto``, the default: one animated mesh, with the method chosen from the data.

The rule (``kinematic`` first; an open surface keeps it; a closed object is closed by the
``flow`` method's surfaces; a shape that splits gives the flow's meshes; then a fit to the
frames) is :mod:`.method`'s; :mod:`.stream` runs the same rule over a whole capture with
memory bounded by a window of frames (``fourd reconstruct --stream``, issue 56).
"""

from fourd.methods.auto.method import (
    COMMON_OPTIONS,
    MEMORY_OPTIONS,
    MIN_FRAMES,
    RESULT,
    AutoDiagnostics,
    Options,
    estimate_peak_bytes,
    fit_points,
    fit_scales,
    fit_to_frames,
    part_counts,
    reconstruct,
    reconstruct_with_diagnostics,
    splits,
    vector_area_fraction,
)
from fourd.methods.auto.stream import StreamSummary, reconstruct_streamed

__all__ = [
    "COMMON_OPTIONS",
    "MEMORY_OPTIONS",
    "MIN_FRAMES",
    "RESULT",
    "AutoDiagnostics",
    "Options",
    "StreamSummary",
    "estimate_peak_bytes",
    "fit_points",
    "fit_scales",
    "fit_to_frames",
    "part_counts",
    "reconstruct",
    "reconstruct_streamed",
    "reconstruct_with_diagnostics",
    "splits",
    "vector_area_fraction",
]
