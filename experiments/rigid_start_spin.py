"""Question: `surfels` on squash-ball drifted to a correspondence error of 0.21 of the diagonal
at the last frame (`kinematic`: 0.0065). Does the alignment's rigid start (point-to-plane ICP,
:func:`fourd.geometry.icp.rigid_icp`) spin the ball, and can a test on the data tell a spin
the surface does not determine from a real turn?

    PYTHONPATH=src python experiments/rigid_start_spin.py squash-ball rigid-turn bending-arm
    PYTHONPATH=src python experiments/rigid_start_spin.py --surfels 96

For every third frame pair, the truth's frame k (vertices, normals) is fitted rigidly onto the
scan of frame k+1 (outliers removed, PCA normals oriented to the sensors), once with the
rotation and once as a translation alone; printed: the rotation angle found and the two
point-to-plane rms (fractions of the diagonal). The truth has no rotation in squash-ball.

The second runs `surfels` on squash-ball scanned at 96 rays a side (2 minutes) and prints the
correspondence error of each frame (mean distance of each vertex from where its frame-0 point
of the truth went, as a fraction of the diagonal).

Answer (2026-12-01, 2-core machine): yes. On squash-ball the rigid fit turns the ball by 0.35 to
90 degrees between frames (about its vertical axis, a surface of revolution), and that turn
lowers the rms by 0-1% (once 48%, frame 9, the fastest squash). Real turns lower it by 8 to 39%:
rigid-turn (6 degrees a frame) 0.61-0.63 of the translation's rms, bending-arm 0.61-0.92,
crane's larger turns (1-4 degrees) 0.79-0.86; touching-spheres' spurious ones even raise it
(up to 2.3 times). So `rigid_icp(rotation_evidence=0.1)` keeps a rotation only when it lowers
the translation's rms by more than 10%.

That was not enough on the bench (squash-ball's last frame 0.208 -> 0.199): logged in the
merges, two rigid starts turned by 87 and 92 degrees and passed the test, because a ball
squashing from prolate to oblate matches itself turned on its side better than shifted (rms
0.52 of the translation's at frame 9). Refusing turns above 30 degrees between adjacent frames
(`surfels`' `MAX_START_TURN`), `--surfels 96` gives 0.0075 -> 0.235 over the 20 frames before
and 0.0044 -> 0.025 (worst 0.047, frame 5) after, like a translation-only start; from a copy
(the paper) 0.021 at the end. benchmarks/METHODS.md, `surfels`, "The rigid start's turn".
"""

from __future__ import annotations

import sys

import numpy as np
from scipy.spatial.transform import Rotation

from fourd import synth
from fourd.bench.suite import HELD_OUT_SCENES, PROTOCOL, STANDARD_SCENES
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.icp import rigid_icp
from fourd.geometry.normals import estimate_normals, vertex_normals
from fourd.geometry.outliers import distance_ratio_inliers


def scene_and_scans(label: str, resolution: int | None = None):
    scene = next(s for s in STANDARD_SCENES + HELD_OUT_SCENES if s.key == label)
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    rays = resolution or scene.resolution
    return truth, synth.scan(truth, resolution=rays, seed=0, **{**PROTOCOL, **scene.scan})


def surfels_drift(resolution: int) -> None:
    from fourd.methods import reconstruct

    truth, scans = scene_and_scans("squash-ball", resolution)
    result = reconstruct(scans, "surfels")
    found = closest_points_on_mesh(truth.vertices[0], truth.faces, result.vertices[0])
    diagonal = np.linalg.norm(np.ptp(truth.vertices[0], axis=0))
    errors = []
    for t, vertices in enumerate(truth.vertices):
        went = np.einsum("mk,mkd->md", found.barycentric, vertices[truth.faces[found.triangle]])
        errors.append(np.linalg.norm(result.vertices[t] - went, axis=1).mean() / diagonal)
    print("correspondence per frame:", np.round(errors, 4).tolist())


def main(labels) -> None:
    if labels[:1] == ["--surfels"]:
        surfels_drift(int(labels[1]))
        return
    for label in labels:
        truth, scans = scene_and_scans(label)
        for k in range(0, len(truth.vertices) - 1, 3):
            frame = scans.frames[k + 1]
            points = frame.points[distance_ratio_inliers(frame.points, k=8, factor=3.0)]
            normals = estimate_normals(points, sensors=frame.sensors).normals
            source = truth.vertices[k]
            source_normals = vertex_normals(source, truth.faces)
            rigid = rigid_icp(source, points, normals, source_normals=source_normals)
            shift = rigid_icp(source, points, normals, source_normals=source_normals, rotate=False)
            angle = np.degrees(np.linalg.norm(Rotation.from_matrix(rigid.rotation).as_rotvec()))
            diagonal = np.linalg.norm(np.ptp(source, axis=0))
            print(
                f"{label} {k:2d}: turn {angle:6.2f} degrees, rms {rigid.rms / diagonal:.5f} "
                f"against {shift.rms / diagonal:.5f} for a translation ({rigid.rms / shift.rms:.3f})",
                flush=True,
            )


if __name__ == "__main__":
    main(sys.argv[1:])
