"""Question: does the wrinkling step (thesis chapter 4) put back the folds a capture missed, and
which of its settings matter on our meshes?

Setup: six frames of the ``tshirt`` truth with folds (frames 2-7 of 20), its folds smoothed away
(``geometry.low_pass`` at a tenth of the diagonal: what a capture that misses shallow folds
gives), and the truth filmed by the standard 3-camera rig in plain fabric under diffuse light
(``lighting="diffuse"``, 512 pixels). The fold edges are found once; the space-time rotations
and the positioning are rerun per setting. Scored by ``metrics.folds.fold_recall`` (truth folds
deeper than 0.5% of the diagonal with a result fold within 1%) and the mean vertex distance to
the truth (the truth's own connectivity: exact correspondence).

Run: ``.venv/bin/python experiments/wrinkles_from_video.py``

Answer (2-core machine, 2026-11-27): the smoothed input has recall 0.00 (vertex error 0.0026).
With the thesis' weights (cs 0.9, ct 0.5, ci 0.1, ca 10), three views, no stretch reduction:

| views | setting | recall | precision | vertex error |
|---|---|---|---|---|
| 2 | pull 1e-4 (about the thesis' one fixed vertex), 2 stretch passes | 0.12 | 0.83 | 0.0033 |
| 2 | pull 1e-4, no stretch pass | 0.22 | 0.90 | 0.0037 |
| 2 | pull 0.1, no stretch pass | 0.17 | 0.94 | 0.0025 |
| 2 | pull 0.1, one stretch pass | 0.09 | 0.88 | 0.0023 |
| 2 | pull 0.1, ci 0.01 | 0.21 | 0.93 | 0.0031 |
| 3 | pull 1e-4, 2 stretch passes | 0.23 | 0.83 | 0.0041 |
| 3 | pull 1e-4, no stretch pass | 0.31 | 0.83 | 0.0047 |
| 3 | pull 0.1, no stretch pass (the defaults) | 0.25 | 0.89 | 0.0026 |
| 3 | pull 0.1, one stretch pass | 0.15 | 0.86 | 0.0023 |
| 3 | pull 0.1, ci 0.01 | 0.31 | 0.89 | 0.0032 |

- The folds come back where the truth has them (precision about 0.9, anchor normals 22 -> 8
  degrees from the truth's), but at about 60% of the truth's depth: the thesis' rotation angles
  (60 degrees for a frame's narrowest fold, 30 for its widest) set slopes, not depths, and
  the depth the rotation field reaches depends on how far it spreads (in triangles).
- A weak pull to the input (0.1 of one edge's term) keeps the far side of the garment from
  drifting as rotations are integrated (vertex error 0.0047 -> 0.0026 with three views) for a
  little depth; every camera of the small rig finds more folds than the best two.
- Stretch reduction (4.5.5: rotations from the normals' change, positions again) flattens the
  folds on these meshes (a few edges per fold): each pass halves the recall; off by default.
- Subdividing the mesh first (as the thesis' 100K-triangle meshes are fine) halves the recall
  instead: the rotations spread over a fixed number of triangles, so over half the distance.
- Under the studio's directional lamps (the other bench scenes), "dark equals deep" does not
  hold: displacements are uncorrelated with the truth's folds (correlation -0.05 to -0.09).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fourd import synth
from fourd.animation import AnimatedMesh
from fourd.geometry.low_pass import low_pass_surface
from fourd.methods.garment.wrinkling import (
    WrinkleOptions,
    positioned_frames,
    spacetime_rotations,
    wrinkle,
)
from fourd.metrics.folds import fold_recall


def _positions(smooth, faces, anchors, options: WrinkleOptions):
    return positioned_frames(smooth, faces, spacetime_rotations(faces, len(smooth), anchors, options), options)


def main() -> None:
    truth = synth.scene("tshirt", frames=20)
    frames = AnimatedMesh(truth.faces, truth.vertices[2:8])
    video = synth.scan(frames, resolution=48, appearance="uniform", video=True, video_resolution=512,
                       lighting="diffuse").video
    diagonal = frames.diagonal()
    faces = frames.faces
    smooth = np.stack([low_pass_surface(v, faces, 0.1 * diagonal) for v in frames.vertices])

    def report(label, vertices):
        score = fold_recall(AnimatedMesh(faces, vertices), frames)
        error = np.linalg.norm(vertices - frames.vertices, axis=2).mean() / diagonal
        print(f"{label:<55} recall {score['fold_recall']:.2f}  precision {score['fold_precision'] or 0:.2f}  "
              f"vertex error {error:.4f}")

    report("smoothed input", smooth)
    for views in (2, 3):
        base = WrinkleOptions(anchors=dataclasses.replace(WrinkleOptions().anchors, views=views))
        anchors = wrinkle(smooth, faces, video, base).anchors
        for label, change in (
            ("pull 1e-4, 2 stretch passes", {"pull": 1e-4, "stretch_iterations": 2}),
            ("pull 1e-4", {"pull": 1e-4}),
            ("defaults", {}),
            ("one stretch pass", {"stretch_iterations": 1}),
            ("ci 0.01", {"identity": 0.01}),
        ):
            report(f"{views} views, {label}", _positions(smooth, faces, anchors, dataclasses.replace(base, **change)))


if __name__ == "__main__":
    main()
