"""Method ``flow``: space-time reconstruction with incompressible flow.

The object is a 4D solid on a space-time grid; its characteristic function ``x`` and a flow
``v`` of material between temporally adjacent cells of consecutive time slices are solved for
together, so that material is conserved (incompressibility), moves smoothly (momentum), and
the function is piecewise constant in space (continuity with a sub-linear norm, by IRLS). A
Laplace solve turns the result into a 4D implicit function and marching cubes gives a closed,
manifold mesh per frame, also for frames without any data.

Pipeline (modules of this package):

1. :mod:`.grid` -- space-time grid, outlier filter, visual hull from the sensors, inside seeds;
   :mod:`.fit` -- low-resolution smooth 4D implicit fit (improves labels, orients normals);
2. :mod:`.system` -- the constrained quadratic (continuity, momentum, regulariser,
   incompressibility constraints);
3. :mod:`.irls` -- reweighting, bootstrapping and clamping until 90-95% of cells are decided;
4. :mod:`.saddle` -- MINRES (:mod:`.krylov`) with the block-diagonal preconditioner, its
   inner solves by AMG (:mod:`.amg`);
5. :mod:`.post` -- refinement near the surface, Laplace solve, :class:`FlowField`, marching cubes.

Longer sequences are solved in overlapping windows whose surfaces are blended over the frames
they share (:mod:`.windows`, ``Options.window``); :func:`reconstruct_streamed` reads the frames
and writes the meshes a window at a time.

:func:`estimate_peak_bytes` (:mod:`.memory`) tells the memory a run will need before it starts
(the up-front check of :mod:`fourd.preflight`).

References
----------
Sharf, Alcantara, Greif, Lewiner, Sheffer, Amenta, Cohen-Or: Space-time surface reconstruction
using incompressible flow. ACM Transactions on Graphics 27(5), SIGGRAPH Asia 2008
(``002_382acf333feb7a6e.txt``).
"""

from fourd.methods.flow.memory import MEMORY_OPTIONS, estimate_peak_bytes
from fourd.methods.flow.method import reconstruct, reconstruct_with_diagnostics
from fourd.methods.flow.options import COMMON_OPTIONS, MIN_FRAMES, RESULT, Options
from fourd.methods.flow.pipeline import (
    FlowDiagnostics,
    FlowResult,
    mass_conservation_error,
    run,
    surface_distance,
)
from fourd.methods.flow.post import FlowField, mesh_distance
from fourd.methods.flow.saddle import SaddleSolution, solve_saddle
from fourd.methods.flow.windows import STREAM_WINDOW, reconstruct_streamed, window_ranges

__all__ = [
    "COMMON_OPTIONS",
    "MEMORY_OPTIONS",
    "MIN_FRAMES",
    "FlowDiagnostics",
    "FlowField",
    "FlowResult",
    "Options",
    "SaddleSolution",
    "STREAM_WINDOW",
    "estimate_peak_bytes",
    "mass_conservation_error",
    "mesh_distance",
    "reconstruct",
    "reconstruct_with_diagnostics",
    "RESULT",
    "reconstruct_streamed",
    "run",
    "solve_saddle",
    "window_ranges",
    "surface_distance",
]

