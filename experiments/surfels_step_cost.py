"""Issue 50 (speed, peak memory): what does one ``surfels`` global optimisation cost, in time
and in memory, and which part of a Gauss-Newton step takes it?

The largest optimisation of a streamed run (``experiments/surfels_long_capture.py``'s capture,
20 frames in windows of 10: the second window's merge, 14 frames and 444 surfels at 6f8067a)
is captured to a pickle, then timed alone: ``total_energy`` (the Hessian's assembly) and
``solve_step`` with their ``tracemalloc`` peaks, and the whole ``gauss_newton`` with its
peak resident memory (each timing in a fresh process).

Answer (2-core Intel Xeon, nothing else running; benchmarks/METHODS.md, "The normal
equations' copies"): at 6f8067a ``total_energy`` 1.61 s, peak 391 MB; ``solve_step`` 227 MB
more; ``gauss_newton`` 7.58 s, 728 MB. At 41f7844: 0.57-0.75 s, 250 MB; 95 MB; 5.6 s, 565 MB.
At 3356095 (the priors' patterns kept, their structural zeros left out; "The priors' Jacobian
patterns kept"): ``gauss_newton`` 5.00-5.81 s against 6.25-6.97 at 8e04352, run alternately.

Run from the repository root::

    .venv/bin/python experiments/surfels_step_cost.py capture   # about 2 minutes
    .venv/bin/python experiments/surfels_step_cost.py parts
    .venv/bin/python experiments/surfels_step_cost.py whole
"""

from __future__ import annotations

import pickle
import resource
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

PROBLEM = Path(tempfile.gettempdir()) / "fourd-surfels-step-problem.pkl"


def capture() -> None:
    """Run the streamed 20 frames, keeping the largest ``gauss_newton`` problem."""
    import surfels_long_capture

    from fourd.methods.surfels import assembly

    largest = [0]
    solve = assembly.gauss_newton

    def keep(state, topology, data, weights=None, match=None, options=None, **kw):
        if state.frames * state.count > largest[0]:
            largest[0] = state.frames * state.count
            PROBLEM.write_bytes(pickle.dumps((state, topology, data, weights, match, options, kw)))
        return solve(state, topology, data, weights, match, options, **kw)

    assembly.gauss_newton = keep
    surfels_long_capture.run(20)


def _load():
    return pickle.loads(PROBLEM.read_bytes())


def parts() -> None:
    from fourd.methods.surfels.energy import total_energy
    from fourd.methods.surfels.match import associate
    from fourd.methods.surfels.optimizer import solve_step
    from fourd.methods.surfels.state import layout

    state, topology, data, weights, match, options, kw = _load()
    columns = None if kw.get("free") is None else np.flatnonzero(kw["free"])
    matches = associate(state, data, topology.radius, match)
    print(f"{state.frames} frames, {state.count} surfels")
    tracemalloc.start()
    started = time.perf_counter()
    energy = total_energy(
        state, topology, data, matches, weights, match, columns=columns,
        urshape=kw.get("urshape", False),
    )
    seconds, peak = time.perf_counter() - started, tracemalloc.get_traced_memory()[1]
    hessian = energy.hessian
    print(f"total_energy {seconds:.2f} s, peak {peak / 2**20:.0f} MB; Hessian "
          f"{hessian.shape[0]} unknowns, {hessian.nnz} nonzeros")
    tracemalloc.reset_peak()
    held = tracemalloc.get_traced_memory()[0]
    started = time.perf_counter()
    solve_step(hessian, energy.gradient, layout(state), options, columns=columns)
    seconds, peak = time.perf_counter() - started, tracemalloc.get_traced_memory()[1]
    print(f"solve_step {seconds:.2f} s, {(peak - held) / 2**20:.0f} MB more")


def whole() -> None:
    from fourd.methods.surfels.optimizer import gauss_newton

    state, topology, data, weights, match, options, kw = _load()
    started = time.perf_counter()
    result = gauss_newton(state, topology, data, weights, match, options, **kw)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"gauss_newton {time.perf_counter() - started:.2f} s, peak resident {peak:.0f} MB, "
          f"energy {result.energies[0]:.6g} -> {result.energies[-1]:.6g}")


if __name__ == "__main__":
    {"capture": capture, "parts": parts, "whole": whole}[sys.argv[1]]()
