"""The ``flow`` method's entry points: one solve over the sequence (:func:`~.pipeline.run`),
or windows of ``Options.window`` frames blended over the frames they share
(:mod:`~.windows`)."""

from __future__ import annotations

from fourd.animation import MeshSequence
from fourd.methods.base import Reconstruction
from fourd.methods.flow.options import Options
from fourd.methods.flow.pipeline import FlowDiagnostics, run
from fourd.methods.flow.windows import reconstruct_windowed
from fourd.sequence import PointCloudSequence


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> MeshSequence:
    """Closed, manifold meshes per frame.

    The mass conservation error is logged at info level; :func:`~.pipeline.run` returns it
    with every other intermediate result (one solve), :func:`reconstruct_with_diagnostics`
    also for windows.
    """
    return reconstruct_with_diagnostics(seq, options).result


def reconstruct_with_diagnostics(
    seq: PointCloudSequence, options: Options | None = None
) -> Reconstruction:
    """:func:`reconstruct` and :class:`~.pipeline.FlowDiagnostics` (the paper's mass
    conservation error, over the whole sequence also when it is solved in windows)."""
    options = Options() if options is None else options
    if options.window and len(seq) > options.window:
        result = reconstruct_windowed(seq, options)
    else:
        result = run(seq, options)
    return Reconstruction(result.meshes, FlowDiagnostics(float(result.mass_error)))
