"""Issue 50 (speed): do the conjugate gradients limit a ``surfels`` Gauss-Newton step, and
does a stronger block preconditioner cut their iterations?

On the problem ``surfels_step_cost.py capture`` pickles (the largest optimisation of the
streamed 20 frames), ``gauss_newton`` runs with a given CG iteration cap and either the
method's block-Jacobi preconditioner (3x3 position, 2x2 normal offset, 3x3 rotation blocks) or
8x8 blocks (a surfel's position, normal offset and rotation in one frame together); it prints
the time, the energy after each step and the CG iterations run.

Answer (2-core Intel Xeon, at 3356095; benchmarks/METHODS.md, "The priors' Jacobian patterns
kept"): the steps are not CG-limited. 50 iterations (default) 143,132 after 4 steps in 6.07 s;
150 (converged after 88-125) 143,313; 25: 143,482 in 4.42 s; 12: 144,742 in 3.68 s; the 8x8
blocks at 50: 143,107, no faster.

Run from the repository root (after ``surfels_step_cost.py capture``)::

    .venv/bin/python experiments/surfels_cg_iterations.py block 50
    .venv/bin/python experiments/surfels_cg_iterations.py group 50
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

import numpy as np
import scipy.sparse as sp


def group_jacobi(system: sp.csr_matrix, free: np.ndarray, lay) -> sp.csr_matrix:
    """Inverse 8x8 diagonal blocks of ``system`` (rows and columns ``free`` of the layout):
    position, normal offset and rotation of one surfel in one frame (fewer where not free)."""
    group = np.empty(lay.size, dtype=np.int64)
    group[: lay.normals_start] = np.arange(lay.normals_start) // 3
    normals = lay.rotations_start - lay.normals_start
    group[lay.normals_start : lay.rotations_start] = np.arange(normals) // 2
    group[lay.rotations_start :] = np.arange(lay.size - lay.rotations_start) // 3
    owner = group[free]
    order = np.argsort(owner, kind="stable")
    _, index, sizes = np.unique(owner, return_inverse=True, return_counts=True)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    rank = np.empty(len(free), dtype=np.int64)
    rank[order] = np.arange(len(free))
    member = rank - starts[index]
    system = system.tocsr()
    rows = np.repeat(np.arange(system.shape[0]), np.diff(system.indptr))
    same = index[rows] == index[system.indices]
    blocks = np.zeros((len(sizes), 8, 8))
    np.add.at(
        blocks,
        (index[rows[same]], member[rows[same]], member[system.indices[same]]),
        system.data[same],
    )
    blocks[:, np.arange(8), np.arange(8)] += np.arange(8)[None, :] >= sizes[:, None]
    inverse = np.linalg.inv(blocks)
    row = np.repeat(np.arange(len(free)), sizes[index])
    other = np.concatenate([np.arange(k) for k in sizes[index]])
    column = order[starts[index[row]] + other]
    values = inverse[index[row], member[row], other]
    return sp.csr_matrix((values, (row, column)), shape=(len(free), len(free)))


def main(preconditioner: str, iterations: int) -> None:
    sys.path.insert(0, "experiments")
    import surfels_step_cost

    from fourd.methods.surfels import optimizer

    if preconditioner == "group":
        optimizer._block_jacobi = group_jacobi
    state, topology, data, weights, match, options, kw = surfels_step_cost._load()
    options = replace(options, cg_iterations=iterations)
    started = time.perf_counter()
    result = optimizer.gauss_newton(state, topology, data, weights, match, options, **kw)
    print(
        f"{preconditioner} {iterations}: {time.perf_counter() - started:.2f} s, energies "
        f"{np.round(result.energies).astype(int).tolist()}, CG {result.cg_iterations.tolist()}"
    )


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
