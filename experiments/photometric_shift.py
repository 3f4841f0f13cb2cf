"""Question: do the colours of the points alone (no video) say where the skin went, well enough
to correct the sliding's drift? On the true positions of each frame, shifted along the surface by
a known amount, does a per-vertex Lucas-Kanade on the points' colours (against the colours the
vertices had at frame 0) recover the shift, with raw colours and with the fixed lamps' shading
divided out?

    python experiments/photometric_shift.py crane skin 20

Environment: ``NK`` (normal neighbours, 16), ``SM`` (colour smoothing neighbours, 8), ``RAD``
(patch radius in hundredths of the diagonal, 3), ``BR`` (brightness offset: shared, channel,
none), ``DESHADE`` (0,1: divide the points' colours by the fitted lamps' shading).

Answer (crane, 20 frames, standard scan, 6000 truth vertices; median distance to the truth of
the confident vertices, started on the truth / 0.005 D off it, frames 1 and 13): printed cloth
0.0015 / 0.0019 at frame 1 and 0.0023 / 0.0027 at frame 13, so the colours correct a shift of
0.005 to about 0.002 (the noise floor of one vertex; the tracking averages it over many).
Skin: 0.0019 at frame 1 but 0.0063 at frame 13, as far off as the shift it should correct: the
skin's albedo varies by a few per cent, less than the shading changes when a limb turns, and
dividing the points' colours by the fitted shading (``DESHADE=1``) is worse (0.0051 at frame 1:
the points' normals are too noisy to read the shading at). Two fixes on the way: a plain mean
of neighbours' colours is biased on irregular samples (the local linear fit's value is not),
and a per-channel brightness offset cannot tell a shift from an offset where the colour
changes linearly across the patch (one offset shared by the channels can).
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from fourd import synth
from fourd.bench.suite import PROTOCOL, STANDARD_SCENES
from fourd.geometry.normals import estimate_normals, vertex_normals


def main(name: str, appearance: str, frames: int) -> None:
    from fourd.appearance.lighting import fit_lighting
    from fourd.appearance.photometric import photometric_shift
    from fourd.appearance.surface_color import ColorField

    scene = next(s for s in STANDARD_SCENES if s.key == name)
    count = frames if scene.frames is None else min(frames, scene.frames)
    truth = synth.scene(scene.name, frames=count, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, appearance=appearance, **PROTOCOL)
    diagonal = float(truth.diagonal())
    neighbours, smoothing = int(os.environ.get("NK", 16)), int(os.environ.get("SM", 8))
    radius = float(os.environ.get("RAD", 3))
    normals = [estimate_normals(f.points, k=neighbours, sensors=f.sensors).normals for f in scans.frames]
    started = time.perf_counter()
    lighting = fit_lighting([f.points for f in scans.frames], normals, [f.colors for f in scans.frames])
    print(f"lighting fit {time.perf_counter() - started:.2f} s, residual {lighting.residual:.4f}")
    rng = np.random.default_rng(1)
    template = np.sort(rng.choice(truth.vertex_count, min(6000, truth.vertex_count), replace=False))
    edge = diagonal * 0.01
    for deshade in [bool(int(x)) for x in os.environ.get('DESHADE', '0,1').split(',')]:
        fields = [ColorField(f.points, n, f.colors, lighting=lighting if deshade else None, smoothing=smoothing)
                  for f, n in zip(scans.frames, normals, strict=True)]
        reference = fields[0].sample(truth.vertices[0][template])
        for shift in (0.0, 0.005):
            gains, biases = [], []
            for t in range(1, count, max(1, count // 5)):
                true = truth.vertices[t][template]
                vn = vertex_normals(truth.vertices[t], truth.faces)[template]
                direction = np.cross(vn, [0.3, 1.0, 0.2])
                direction /= np.linalg.norm(direction, axis=1, keepdims=True)
                offset = shift * diagonal * direction
                start = true + offset
                s = time.perf_counter()
                result = photometric_shift(start, vn, reference, fields[t], radius=radius * edge, brightness=os.environ.get("BR", "shared"))
                took = time.perf_counter() - s
                ok = result.uncertainty < 0.5 * edge
                before = np.linalg.norm(start - true, axis=1)[ok]
                after = np.linalg.norm(start + result.shift - true, axis=1)[ok]
                gains.append(np.median(after) / diagonal)
                biases.append(np.median(before) / diagonal)
                print(f"  deshade={deshade} shift={shift} t={t}: confident {ok.mean():.2f}, error "
                      f"{np.median(before) / diagonal:.4f} -> {np.median(after) / diagonal:.4f} "
                      f"(mean {np.mean(after) / diagonal:.4f}) {took:.2f} s", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
