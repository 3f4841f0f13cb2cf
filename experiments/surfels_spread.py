"""Question (issue 50): how far do `surfels`' scores move from rounding alone? The optimiser
stops after a fixed number of steps and its discrete decisions (the matching's cutoffs, the
resampling, the part search, the border clipping) amplify rounding differences, so the same
commit scores differently on another machine or numpy build. Earlier notes call changes
"within the spread" without a measured spread; this measures it on one environment.

Each run reconstructs the bench's scan of a scene with every point moved by a random offset of
1e-9 times the scene's diagonal (seeded; run 0 unmoved; ``fourd.bench.spread.moved_scans``),
far below the scan's noise but far above rounding, and scores it as ``fourd bench`` does (same
samples and seed). ``fourd bench --spread N`` now makes such rows itself.

Run from the repository root::

    PYTHONPATH=src .venv/bin/python experiments/surfels_spread.py crane 6

Answer (2-core AMD EPYC, numba for znver4, 2026-12-07): crane median 0.0037 / 0.0161 / 0.0093 /
0.0119 (ranges 0.0034-0.0038, 0.0150-0.0170, 0.0090-0.0096, 0.0105-0.0126); crane-90 last
frame 0.0154-0.0229. benchmarks/METHODS.md, "How far rounding alone moves the scores".
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

import fourd
from fourd.bench.spread import moved_scans
from fourd.bench.suite import SAMPLES, scan_scene, select_scenes
from fourd.metrics.scores import evaluate

KEYS = ("chamfer", "completeness_95", "correspondence_mean", "correspondence_last", "jitter")


def main(scene: str, runs: int) -> None:
    (bench_scene,) = select_scenes([scene], quick=False)
    truth, scans = scan_scene(bench_scene, 0)
    rows = []
    for seed in range(runs):
        started = time.perf_counter()
        result = fourd.reconstruct(moved_scans(scans, seed), method="surfels")
        seconds = time.perf_counter() - started
        metrics = evaluate(result, truth, samples=SAMPLES, seed=0)
        row = {key: float(metrics[key]) for key in KEYS}
        rows.append(row)
        print(
            f"run {seed}: "
            + " / ".join(f"{row[key]:.4f}" for key in KEYS)
            + f"  ({seconds / len(scans):.2f} s/frame)",
            flush=True,
        )
    for key in KEYS:
        values = np.array([row[key] for row in rows])
        print(
            f"{key}: median {np.median(values):.4f}, range {values.min():.4f}-{values.max():.4f}"
        )
    print(json.dumps(rows))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
