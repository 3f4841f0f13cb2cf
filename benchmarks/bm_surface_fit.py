"""Time :func:`fourd.geometry.surface_fit.fit_along_normals`, the default method's fit to the
frames (``auto`` step 5), on the crane: the truth's first 8 frames (about 10,000 vertices)
fitted to their standard scans (about 15,000 points per frame).

Run: ``.venv/bin/python benchmarks/bm_surface_fit.py``. Prints the seconds per frame of the
fit (best of three) and of one :func:`~fourd.geometry.surface_fit.normal_offsets` pass.
"""

from __future__ import annotations

import time

import numpy as np

from fourd import synth
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.normals import vertex_normals
from fourd.geometry.surface_fit import fit_along_normals, normal_offsets

FRAMES = 8


def main() -> None:
    truth = synth.scene("crane", frames=FRAMES)
    frames = [frame.points for frame in synth.scan(truth, seed=0).frames]
    spacing = point_spacing(frames[0])
    vertices = truth.vertices.astype(np.float64)
    fit = passes = np.inf
    for _ in range(3):
        started = time.perf_counter()
        fit_along_normals(vertices, truth.faces, frames, radius=2 * spacing, reach=4 * spacing)
        fit = min(fit, (time.perf_counter() - started) / FRAMES)
        normals = vertex_normals(vertices[0], truth.faces)
        started = time.perf_counter()
        normal_offsets(vertices[0], normals, frames[0], radius=2 * spacing, reach=4 * spacing)
        passes = min(passes, time.perf_counter() - started)
    print(f"crane, {vertices.shape[1]} vertices, {len(frames[0])} points per frame: "
          f"fit {fit:.3f} s/frame, one normal_offsets pass {passes:.3f} s")


if __name__ == "__main__":
    main()
