"""Question (issue 50, speed): after the merges side by side, crane's top merges and final
optimisation run alone, and a cProfile of the bench's 20 frames (``workers=1``) spent most of
its time on one core in scipy and numpy: the conjugate gradients' Hessian products, ``J^T J``,
the Jacobian's transposition, and the association's k-d tree queries. How much do the parallel
products of ``fourd.geometry.sparse_products``, the Hessian as its upper triangle and the
association from the step before save, on the largest merge?

Run from the repository root::

    PYTHONPATH=src .venv/bin/python experiments/surfels_sparse_algebra.py capture
    PYTHONPATH=src .venv/bin/python experiments/surfels_sparse_algebra.py merge
    PYTHONPATH=src .venv/bin/python experiments/surfels_sparse_algebra.py kernels

``capture`` keeps the inputs of the bench's crane merge of frames 0-7 with 8-15 (the 8 + 8
merge, level 4), its largest Hessian system and one association of its 16-frame global
optimisation; ``merge`` times that merge twice; ``kernels`` times a Hessian product (scipy,
``multiply_add`` on the whole matrix with one and two threads, ``symmetric_multiply`` on the
upper triangle), the transposition (scipy, ``csr_transpose``) and the association (from
scratch, and from a slightly moved state's association).

Answer (2-core AMD EPYC, numba for ``znver4``, nothing else running, 2026-12-07): the merge
took 24.2 s at 18913e2, 19.3 s with ``J^T J`` and the products on both cores (0df8a95),
17.8 s with the association from the step before (c208d62), 15.0 s with the upper triangle
(d08e99a). Its largest system: 174,750 unknowns, 28.4 million nonzeros (14.3 million on and
above the diagonal); a product 24.7 ms in scipy, 24.3 / 18.1 ms with one / two threads,
8.8 ms from the upper triangle. The Jacobian (3.4 million rows, 19.8 million nonzeros)
transposed in 148 ms by scipy, 91 ms by ``csr_transpose``. The association (229,375 points,
1,398 surfels a frame, 16 frames): 88 ms from scratch, 37 ms from the one before, the same
surfels. Rerun at 5bcc09c (its own capture: 173,500 unknowns, 27.9 million nonzeros): a
product 24.2 ms in scipy, 24.3 / 20.4 ms, 9.1 ms; the transposition 147 / 94 ms; the
association 68 / 27 ms, the same surfels. Bench: benchmarks/METHODS.md, "Speed: the sparse
algebra on both cores".
"""

from __future__ import annotations

import dataclasses
import pickle
import sys
import time
from pathlib import Path

import numpy as np
from surfels_side_by_side import capture_merges

MERGE = Path("/tmp/surfels_sparse_algebra_merge.pkl")
SYSTEM = Path("/tmp/surfels_sparse_algebra_system.pkl")


def capture() -> None:
    import fourd.methods.surfels.energy as energy
    import fourd.methods.surfels.optimizer as optimizer
    from fourd.methods.surfels.assembly import merge

    capture_merges([(0, 16)], MERGE)
    kept: dict = {}
    product, associate = energy.csr_product, optimizer.associate

    def keep_product(a, b, **kwargs):
        result = product(a, b, **kwargs)
        if result.nnz > kept.get("nnz", 0):
            kept.update(nnz=result.nnz, upper=result, jacobian=b)
        return result

    def keep_association(state, data, scale, match=None, **kwargs):
        if state.frames == 16 and "association" not in kept:
            kept["association"] = (state, data, scale, match)
        return associate(state, data, scale, match, **kwargs)

    energy.csr_product, optimizer.associate = keep_product, keep_association
    merge(*pickle.loads(MERGE.read_bytes())[0])
    SYSTEM.write_bytes(pickle.dumps(kept))
    print(f"kept {MERGE} and {SYSTEM}")


def time_merge() -> None:
    from fourd.methods.surfels.assembly import merge

    job = pickle.loads(MERGE.read_bytes())[0]
    for _ in range(2):
        started = time.perf_counter()
        merge(*job)
        print(f"merge of frames 0-7 with 8-15: {time.perf_counter() - started:.1f} s")


def _milliseconds(run, repeats: int = 10) -> float:
    run()
    started = time.perf_counter()
    for _ in range(repeats):
        run()
    return (time.perf_counter() - started) / repeats * 1e3


def kernels() -> None:
    import numba
    import scipy.sparse as sp

    from fourd.geometry.sparse_products import csr_transpose, multiply_add, symmetric_multiply
    from fourd.methods.surfels.match import associate

    kept = pickle.loads(SYSTEM.read_bytes())
    upper = kept["upper"]
    full = (upper + sp.triu(upper, k=1).T).tocsr()
    x = np.random.default_rng(0).standard_normal(full.shape[0])
    out = np.zeros_like(x)
    print(f"system: {full.shape[0]} unknowns, {full.nnz} nonzeros, {upper.nnz} upper")
    print(f"product, scipy: {_milliseconds(lambda: full @ x):.1f} ms")
    for threads in (1, numba.get_num_threads()):
        numba.set_num_threads(threads)
        print(f"multiply_add, {threads} threads: {_milliseconds(lambda: multiply_add(full, x, out)):.1f} ms")
    print(f"symmetric_multiply: {_milliseconds(lambda: symmetric_multiply(upper, x, out)):.1f} ms")
    jacobian = kept["jacobian"]
    print(f"jacobian: {jacobian.shape[0]} rows, {jacobian.nnz} nonzeros")
    print(f"transpose, scipy: {_milliseconds(lambda: jacobian.T.tocsr(), 5):.0f} ms")
    print(f"csr_transpose: {_milliseconds(lambda: csr_transpose(jacobian), 5):.0f} ms")
    state, data, scale, match = kept["association"]
    before = associate(state, data, scale, match)
    moved = dataclasses.replace(
        state,
        positions=state.positions
        + np.random.default_rng(1).normal(scale=0.05 * scale, size=state.positions.shape),
    )
    fresh = associate(moved, data, scale, match)
    warm = associate(moved, data, scale, match, previous=before)
    print(
        f"association: {len(data.points)} points, {state.count} surfels, {state.frames} frames; "
        f"from scratch {_milliseconds(lambda: associate(moved, data, scale, match)):.0f} ms, "
        f"from the one before "
        f"{_milliseconds(lambda: associate(moved, data, scale, match, previous=before)):.0f} ms, "
        f"the same surfels {np.array_equal(fresh.surfels, warm.surfels)}"
    )


if __name__ == "__main__":
    {"capture": capture, "merge": time_merge, "kernels": kernels}[sys.argv[1]]()
