"""Question: how does `assembly` do on the whole crane capture (175 frames) at the sparse rig,
and where do its errors come from: the observed vertices, or the geometry completed from
other frames?

Setup: the bench's ``crane-full-sparse`` (all 175 frames, the three whole-volume cameras at
160 rays a side, about 2,600 points a frame), ``assembly`` with its defaults. Every 15th frame:
the distance of each output vertex to the truth's surface (60,000 samples), split by
``observed``, and the edges stretched more than three times their length in frame 0.

Run: ``.venv/bin/python experiments/assembly_whole_capture.py [RAYS]`` (about 4 minutes).

Answer (2-core machine, 2026-12-01, at 2b25b7a; the bench's row: Chamfer 0.0069,
completeness-95 0.0545, correspondence 0.0383 mean / 0.0720 last, 1.10 s/frame, 815 MB):

- The observed vertices sit on their frame's data all along: median 0.0015-0.0020 of the
  diagonal, 99th percentile 0.0041-0.0071 from frame 15 on.
- The completed ones (15-28% of the vertices a frame at this density) drift off: median
  0.0025-0.0046, 99th percentile 0.010-0.037, the farthest 0.016 by frame 15 and 0.044-0.074
  from frame 60 on (the blue fins of the bench's picture); edges stretched over 3x grow from
  128 (frame 15) to 918 (frame 165).
- The correspondence error climbs in steps at the fast motions (frames 20-25, 45-50, 70-75,
  ...) and never comes back: every consecutive pair of frames is mapped exactly once in the
  hierarchy, so frame t's correspondence is the composition of t pair maps, and the errors of
  the hard pairs add up. The 20-frame held-out stretches show the size of one such step
  (crane-50: 0.0151 / 0.0245).
- The dense rig (``crane-full``, 400 rays, at 55f0ca1) climbs the same staircase, lower:
  correspondence 0.0137 / 0.0229, Chamfer 0.0026. The chain, not the density.
"""

from __future__ import annotations

import sys

import numpy as np
from scipy.spatial import cKDTree

from fourd import synth
from fourd.geometry.surface_samples import sample_surface
from fourd.methods import reconstruct


def main() -> None:
    rays = int(sys.argv[1]) if len(sys.argv) > 1 else 160
    truth = synth.scene("crane", frames=175, start=0, step=1)
    scans = synth.scan(truth, resolution=rays, seed=0)
    result = reconstruct(scans, "assembly")
    vertices, faces, observed = result.vertices, result.faces, result.observed
    diagonal = truth.diagonal()
    first = np.linalg.norm(vertices[0][faces[:, 0]] - vertices[0][faces[:, 1]], axis=1)
    print("frame | observed | observed: median / 99th pct | completed: median / 99th pct / largest | edges over 3x")
    for t in range(0, len(vertices), 15):
        samples = sample_surface(truth.vertices[t], truth.faces, 60000, np.random.default_rng(0)).points
        distance = cKDTree(samples).query(vertices[t])[0] / diagonal
        stretch = np.linalg.norm(vertices[t][faces[:, 0]] - vertices[t][faces[:, 1]], axis=1) / np.maximum(first, 1e-12)
        seen = observed[t]
        completed = distance[~seen] if (~seen).any() else np.zeros(1)
        print(f"{t} | {seen.mean():.2f} | {np.median(distance[seen]):.4f} / {np.percentile(distance[seen], 99):.4f} | "
              f"{np.median(completed):.4f} / {np.percentile(completed, 99):.4f} / {completed.max():.3f} | "
              f"{int((stretch > 3).sum())}")


if __name__ == "__main__":
    main()
