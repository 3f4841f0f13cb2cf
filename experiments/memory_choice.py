"""Question: can the default pick ``kinematic``'s ``shape_memory`` (0 or 0.5) from the data alone,
by which of the two tracked surfaces explains each frame's points better, and does that choice
agree with the truth's correspondence?

    python experiments/memory_choice.py crane crane-50 bending-arm ...

Prints per scene and setting: the data residual (mean over frames of the mean distance from each
frame's inlier points to the tracked surface, capped at 10 point spacings, in spacings), the
fraction of points farther than 3 spacings, and the truth's correspondence mean / last frame.

Answer: see the end of this docstring (filled in when measured).
"""

from __future__ import annotations

import sys
import time

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from fourd.geometry.neighbors import point_spacing
from fourd.geometry.outliers import distance_ratio_inliers
from fourd.methods import kinematic
from fourd.metrics import evaluate

sys.path.insert(0, "experiments")
from normal_fit import scans_of  # noqa: E402


def residual(anim, frames, spacing):
    means, far = [], []
    for t, points in enumerate(frames):
        mesh = trimesh.Trimesh(anim.vertices[t], anim.faces, process=False)
        samples, _ = trimesh.sample.sample_surface(mesh, 60000, seed=0)
        d, _ = cKDTree(samples).query(points)
        d = np.minimum(d / spacing, 10.0)
        means.append(d.mean())
        far.append((d > 3).mean())
    return float(np.mean(means)), float(np.max(far))


def main(labels):
    for label in labels:
        truth, scans = scans_of(label)
        frames = [f.points[distance_ratio_inliers(f.points, k=8, factor=3.0)] for f in scans.frames]
        spacing = point_spacing(frames[0])
        for memory in (0.0, 0.5):
            started = time.perf_counter()
            anim = kinematic.reconstruct(scans, kinematic.Options(shape_memory=memory))
            seconds = time.perf_counter() - started
            mean, far = residual(anim, frames, spacing)
            r = evaluate(anim, truth, samples=20000, seed=0)
            print(f"{label} shape_memory={memory} residual {mean:.3f} far(max frame) {far:.4f} "
                  f"corr {r['correspondence_mean']:.4f} / {r['correspondence_last']:.4f} "
                  f"chamfer {r['chamfer']:.4f} ({seconds:.0f} s)", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
