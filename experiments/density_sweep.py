"""Question: how does an animated-mesh method degrade with the scan's density (issue 56: "a
density sweep (points per frame vs correspondence) for every animated-mesh method ... the same
for surfels, assembly and garment as they land")? Does it lose a limb for good when the
points thin out, as `kinematic` did at 2,600 points per frame?

    python experiments/density_sweep.py METHOD [RESOLUTIONS...]

The bench's crane (20 frames, every second capture frame, the standard protocol) scanned at
RESOLUTIONS rays per camera side (default 96 128 160; the bench's standard scan is 256, its
row is in BENCHMARKS.md), METHOD with its defaults. Printed per density: points per frame,
correspondence mean / last, the largest per-frame correspondence error and its frame (a lost
limb shows as a jump that stays), Chamfer, completeness-95 (60,000 samples, as the bench), the
output's vertices, seconds per frame. `experiments/assembly_density.py` is the same sweep for
`assembly` alone, with its answer.

Answer for `surfels` (2-core AMD EPYC, 2026-12-01, at ae13da5, nothing else running; the
256-ray row is the bench's, BENCHMARKS.md; the table with its reading is in
benchmarks/METHODS.md, "Density (issue 56; `experiments/density_sweep.py surfels`)"):

| rays | points a frame | correspondence (largest frame) | Chamfer | compl. 95 | vertices | s/frame |
|---|---|---|---|---|---|---|
| 96 | 2,106 | 0.0209 / 0.0288 (0.0371, frame 12) | 0.0128 | 0.0463 | 835 | 1.56 |
| 128 | 3,737 | 0.0180 / 0.0220 (0.0271, frame 12) | 0.0125 | 0.0515 | 1,168 | 2.93 |
| 160 | 5,841 | 0.0144 / 0.0226 (0.0239, frame 18) | 0.0100 | 0.0443 | 1,883 | 5.49 |

No limb is lost for good (the error comes back down after its worst frame); the geometry
thins with the surfels (`sampling` 4 spacings: 835 mesh vertices at 96 rays, Chamfer 0.0128).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from fourd import synth
from fourd.bench.suite import PROTOCOL
from fourd.methods import reconstruct
from fourd.metrics import evaluate


def main(method: str, resolutions: list[int]) -> None:
    truth = synth.scene("crane", frames=20, seed=0, start=0, step=2)
    for resolution in resolutions:
        scans = synth.scan(truth, resolution=resolution, seed=0, **PROTOCOL)
        points = int(np.median([len(f.points) for f in scans.frames]))
        started = time.perf_counter()
        result = reconstruct(scans, method)
        seconds = (time.perf_counter() - started) / len(scans)
        r = evaluate(result, truth, samples=60000, seed=0)
        curve = np.asarray(r["per_frame"]["correspondence"], dtype=float)
        worst = int(np.nanargmax(curve)) if np.isfinite(curve).any() else -1
        print(f"{method}, crane at {resolution} rays ({points} points a frame): correspondence "
              f"{r['correspondence_mean']:.4f} / {r['correspondence_last']:.4f} (largest "
              f"{np.nanmax(curve):.4f} at frame {worst}), Chamfer {r['chamfer']:.4f}, completeness-95 "
              f"{r['completeness_95']:.4f}, {result.vertex_count} vertices, {seconds:.2f} s/frame", flush=True)


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1], [int(a) for a in sys.argv[2:]] or [96, 128, 160])
