"""Question: how much do anchors from the capture's video (``assembly``'s ``anchors="video"``)
lower `assembly`'s drift, and what is left: the anchors' own error, or the maps between them?

Setup: a bench scene scanned with the bench protocol, coloured, with the rig's 3-camera video
at 256 pixels (the bench's ``*-cloth-video`` scenes). Per frame pair, the video anchors'
error against the truth (their frame-t point bound to the truth's surface by closest point,
followed to frame t+1; fraction of the diagonal), then `assembly` with ``anchors`` geometry
and video (and any ``KEY=VALUE`` options given), its correspondence curve every few frames.

Run: ``.venv/bin/python experiments/assembly_video_anchors.py bending-arm cloth [KEY=VALUE ...]``

Answer: see ``benchmarks/METHODS.md``, `assembly`, "Anchors from the video".
"""

from __future__ import annotations

import os
import sys

import numpy as np

from fourd import synth
from fourd.bench.suite import PROTOCOL, STANDARD_SCENES
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.methods import reconstruct
from fourd.methods.assembly.guides import video_guides
from fourd.metrics import evaluate


def main(name: str, appearance: str, overrides: dict) -> None:
    scene = next(s for s in STANDARD_SCENES if s.key == name)
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, appearance=appearance, video=True,
                       video_resolution=256, **PROTOCOL)
    diagonal = truth.diagonal()
    guides = video_guides(scans, 3.0)
    print("pair | anchors | error median / 90th pct (diagonal)")
    for t, guide in enumerate(guides):
        if not len(guide.source):
            print(f"{t} | 0 |")
            continue
        found = closest_points_on_mesh(truth.vertices[t], truth.faces, guide.source)
        corners = truth.vertices[t + 1][truth.faces[found.triangle]]
        followed = np.einsum("ak,akd->ad", found.barycentric, corners)
        error = np.linalg.norm(followed - guide.target, axis=1) / diagonal
        print(f"{t} | {len(error)} | {np.median(error):.4f} / {np.percentile(error, 90):.4f}")
    for anchors in os.environ.get("ANCHORS", "geometry video").split():
        result = reconstruct(scans, "assembly", anchors=anchors, **overrides)
        scores = evaluate(result, truth, samples=20000)
        curve = scores["per_frame"]["correspondence"]
        print(f"{anchors}: correspondence {scores['correspondence_mean']:.4f} / {scores['correspondence_last']:.4f}, "
              f"Chamfer {scores['chamfer']:.4f}; per frame "
              + " ".join(f"{t}:{curve[t]:.4f}" for t in range(0, len(curve), 3)))


if __name__ == "__main__":
    options = dict(arg.split("=", 1) for arg in sys.argv[3:])
    main(sys.argv[1], sys.argv[2], options)  # strings, converted by the method's options
