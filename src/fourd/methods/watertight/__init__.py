"""Method ``watertight``: one closed animated mesh, the ``kinematic`` result closed by the
``flow`` method's surfaces (a composition of two methods; :mod:`.method`). :mod:`.stream` runs
it over a whole capture with memory bounded by a window of frames (``fourd reconstruct
--stream``, or ``window`` in memory; issue 56).
"""

from fourd.methods.watertight.method import (
    COMMON_OPTIONS,
    LOST_WARNING,
    MEMORY_OPTIONS,
    MIN_FRAMES,
    OFF_SURFACE_CELLS,
    OFF_SURFACE_WARNING,
    RESULT,
    ClosedTemplate,
    Closing,
    Options,
    WatertightDiagnostics,
    carry_frame,
    close_animation,
    close_on_flow,
    closed_frames,
    closed_template,
    estimate_peak_bytes,
    free_offsets,
    lost_fraction,
    off_surface_fraction,
    off_surface_fractions,
    reconstruct,
    reconstruct_with_diagnostics,
    rigid_blend,
)
from fourd.methods.watertight.stream import StreamSummary, reconstruct_streamed

__all__ = [
    "COMMON_OPTIONS",
    "LOST_WARNING",
    "MEMORY_OPTIONS",
    "MIN_FRAMES",
    "OFF_SURFACE_CELLS",
    "OFF_SURFACE_WARNING",
    "RESULT",
    "ClosedTemplate",
    "Closing",
    "Options",
    "StreamSummary",
    "WatertightDiagnostics",
    "carry_frame",
    "close_animation",
    "close_on_flow",
    "closed_frames",
    "closed_template",
    "estimate_peak_bytes",
    "free_offsets",
    "lost_fraction",
    "off_surface_fraction",
    "off_surface_fractions",
    "reconstruct",
    "reconstruct_streamed",
    "reconstruct_with_diagnostics",
    "rigid_blend",
]
