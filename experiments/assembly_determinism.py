"""Question: does ``assembly`` give the same result twice, with its merges in two processes?

Setup: crane frames 0-8 step 2 (5 frames), the standard scan, reconstructed twice by
``assembly`` with ``workers`` processes; the largest difference of a vertex between the runs
(scene units; the diagonal is about 2).

Run: ``.venv/bin/python experiments/assembly_determinism.py [WORKERS]``, at two commits to
compare; ``OPENBLAS_NUM_THREADS=1`` in front to take BLAS's threads out.

Answer (2-core AMD EPYC, 2026-12-03): at 5c25111, ``workers=1`` 0.0 and ``workers=2`` 0.030
(a map alone ran in this process with two BLAS threads, the others in workers with one; with
``OPENBLAS_NUM_THREADS=1`` 0.0). With the lone maps given a worker's BLAS threads
(e421f59): ``workers=2`` 0.0 in three runs of the script, but ``workers=1`` and ``workers=2``
then differed (1.6e-4 on squash-ball, the test
``test_merges_of_a_level_run_in_processes_with_the_same_result``). With every map made with
one BLAS thread wherever it runs (``one_blas_thread`` on ``map_pair``): 0 here, and that test
passes.
"""

from __future__ import annotations

import sys

import numpy as np

from fourd import synth
from fourd.methods import reconstruct


def main() -> None:
    workers = int(sys.argv[1]) if len(sys.argv) > 1 else 2
    scans = synth.scan(synth.scene("crane", frames=5, start=0, step=2), seed=0)
    first = reconstruct(scans, "assembly", workers=workers)
    second = reconstruct(scans, "assembly", workers=workers)
    if first.vertices.shape != second.vertices.shape:
        print(f"workers={workers}: the runs differ in shape, {first.vertices.shape} and {second.vertices.shape}")
        return
    print(f"workers={workers}: largest difference {np.abs(first.vertices - second.vertices).max():.3g}")


if __name__ == "__main__":
    main()
