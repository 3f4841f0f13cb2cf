"""Question: how does `assembly` degrade with the scan's density (issue 56: "the same for
surfels, assembly and garment as they land")? `kinematic` lost the crane's limbs at 2,600
points per frame; does the hierarchy of pair maps?

    python experiments/assembly_density.py [RESOLUTIONS...]

The bench's crane (20 frames, every second capture frame, the standard protocol) scanned at
RESOLUTIONS rays per camera side (default 96 128 160; the bench's standard scan is 256, its
row is in BENCHMARKS.md), `assembly` with its defaults; printed per density: points per frame,
correspondence mean / last, Chamfer, completeness-95 (60,000 samples, as the bench), the
output's vertices, seconds per frame.

Answer (2-core machine, 2026-11-30, nothing else running; the 256-ray row is the bench's at
4e9bbaf):

| rays | points a frame | correspondence | Chamfer | compl. 95 | vertices | s/frame |
|---|---|---|---|---|---|---|
| 96 | 2,106 | 0.0138 / 0.0179 | 0.0041 | 0.0105 | 4,783 | 4.16 |
| 128 | 3,737 | 0.0108 / 0.0138 | 0.0032 | 0.0089 | 8,106 | 3.56 |
| 160 | 5,841 | 0.0088 / 0.0118 | 0.0027 | 0.0075 | 12,358 | 6.02 |
| 256 (bench) | 14,898 | 0.0062 / 0.0090 | 0.0022 | 0.0057 | | 16.85 |

No limb is lost: the errors grow smoothly as the points thin out, about as the point spacing
does, with no jump from one frame to the next. At 2,106 points a frame the 20 frames stay
within issue 56's sparse-rig targets for the whole capture (0.015 / 0.020 correspondence), but
not its Chamfer (0.0041 against 0.003). The pair maps tie each frame to its own data, so a
sparse frame costs resolution, not the track. The time follows the meshes' size (4.16 s/frame
at 96 rays is a noisy measurement beside 3.56 at 128).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from fourd import synth
from fourd.bench.suite import PROTOCOL
from fourd.methods import reconstruct
from fourd.metrics import evaluate


def main(resolutions: list[int]) -> None:
    truth = synth.scene("crane", frames=20, seed=0, start=0, step=2)
    for resolution in resolutions:
        scans = synth.scan(truth, resolution=resolution, seed=0, **PROTOCOL)
        points = int(np.median([len(f.points) for f in scans.frames]))
        started = time.perf_counter()
        result = reconstruct(scans, "assembly")
        seconds = (time.perf_counter() - started) / len(scans)
        r = evaluate(result, truth, samples=60000, seed=0)
        print(f"crane at {resolution} rays ({points} points a frame): correspondence "
              f"{r['correspondence_mean']:.4f} / {r['correspondence_last']:.4f}, Chamfer {r['chamfer']:.4f}, "
              f"completeness-95 {r['completeness_95']:.4f}, {result.vertex_count} vertices, "
              f"{seconds:.2f} s/frame", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [96, 128, 160])
