"""Question (issue 50, speed and peak memory): the conjugate gradients of a ``surfels``
Gauss-Newton step need only products with the Hessian ``2 J^T J``. Is forming it worth its
cost, or is ``2 J^T (J p)`` per iteration cheaper over a step (the product ``J^T J`` and the
Hessian's memory saved, two products with ``J`` per iteration instead of one with ``H``)?

Run from the repository root, after ``experiments/surfels_step_cost.py capture`` (the largest
optimisation of the streamed 20 frames of crane, pickled)::

    PYTHONPATH=src .venv/bin/python experiments/surfels_matrix_free.py

Answer (2-core Intel Xeon, nothing else running, 2026-12-06 at 375a9b0; the problem: 14
frames, 504 surfels, 48,384 unknowns): J has 1,167,164 rows and 6.11 million nonzeros, H 9.16
million. Forming ``J^T J`` takes 0.21 s; a product with H 7.9 ms, ``J^T (J p)`` 12.3 ms. The
4.4 ms more per iteration cost as much as forming H after 48 iterations, and the steps run up
to 50 (``cg_iterations``), which they reach (METHODS, "The priors' Jacobian patterns kept").
No time to gain; H stays formed. (It would save H's memory, about 110 MB here.)
"""

from __future__ import annotations

import time

import numpy as np
from surfels_step_cost import _load

import fourd.methods.surfels.energy as energy_module
from fourd.methods.surfels.energy import total_energy
from fourd.methods.surfels.match import associate


class _Recording:
    """scipy.sparse as the energy module sees it, keeping the stacked Jacobian."""

    def __init__(self, module):
        self.module, self.stacked = module, None

    def __getattr__(self, name):
        return getattr(self.module, name)

    def vstack(self, *args, **kwargs):
        self.stacked = self.module.vstack(*args, **kwargs)
        return self.stacked


def best_of(run, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        run()
        times.append(time.perf_counter() - started)
    return min(times)


def step_system():
    """The step-cost problem's first Gauss-Newton system: its state, whole Hessian and
    stacked Jacobian."""
    state, topology, data, weights, match, options, kw = _load()
    columns = None if kw.get("free") is None else np.flatnonzero(kw["free"])
    matches = associate(state, data, topology.radius, match)
    recording = energy_module.sp = _Recording(energy_module.sp)
    energy = total_energy(
        state, topology, data, matches, weights, match, columns=columns,
        urshape=kw.get("urshape", False),
    )
    energy_module.sp = recording.module
    # the energy keeps the Hessian's upper triangle (since d08e99a): the whole matrix here
    upper = energy.hessian
    return state, (upper + recording.module.triu(upper, k=1).T).tocsr(), recording.stacked


def main() -> None:
    state, hessian, jacobian = step_system()
    transposed = jacobian.T.tocsr()
    print(f"{state.frames} frames, {state.count} surfels, {hessian.shape[0]} unknowns")
    print(f"J {jacobian.shape[0]} rows, {jacobian.nnz} nonzeros; H {hessian.nnz} nonzeros")
    p = np.random.default_rng(0).normal(size=hessian.shape[0])
    formed = best_of(lambda: transposed @ jacobian, 3)
    print(f"J^T J formed: {formed:.3f} s")
    with_h = best_of(lambda: hessian @ p, 20)
    free = best_of(lambda: transposed @ (jacobian @ p), 20)
    print(f"H p {1e3 * with_h:.2f} ms; J^T (J p) {1e3 * free:.2f} ms")
    difference = np.abs(hessian @ p - 2.0 * (transposed @ (jacobian @ p))).max()
    print(f"largest difference {difference:.3g} of {np.abs(hessian @ p).max():.3g}")


if __name__ == "__main__":
    main()
