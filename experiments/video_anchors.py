"""Question: does starting each sliding step where the video's anchors went
(``kinematic`` option ``video_anchors``, :mod:`fourd.methods.kinematic.guide`) reduce the drift?

    python experiments/video_anchors.py bending-arm cloth 20

Prints kinematic's correspondence mean / last frame and Chamfer, with and without the anchors,
on the scene scanned with the bench protocol plus coloured points and the rig's video.

Answer: see the end of this docstring (filled in when measured).
"""

from __future__ import annotations

import sys
import time

from fourd import synth
from fourd.bench.suite import PROTOCOL, STANDARD_SCENES
from fourd.methods import kinematic
from fourd.metrics import evaluate


def main(name: str, appearance: str, frames: int, video_resolution: int = 256) -> None:
    scene = next(s for s in STANDARD_SCENES if s.key == name)
    count = frames if scene.frames is None else min(frames, scene.frames)
    truth = synth.scene(scene.name, frames=count, seed=0, **scene.options)
    scans = synth.scan(truth, resolution=scene.resolution, seed=0, appearance=appearance,
                       video=True, video_resolution=video_resolution, **PROTOCOL)
    for anchors, pull in ((False, 0.0), (True, 0.0), (True, 1.0)):
        started = time.perf_counter()
        result = kinematic.reconstruct(scans, kinematic.Options(video_anchors=anchors, anchor_pull=pull))
        seconds = time.perf_counter() - started
        r = evaluate(result, truth, samples=20000, seed=0)
        print(f"{name} {appearance} video_anchors={anchors} anchor_pull={pull}: correspondence "
              f"{r['correspondence_mean']:.4f} / {r['correspondence_last']:.4f}, Chamfer "
              f"{r['chamfer']:.4f}, {seconds / count:.2f} s/frame", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), *(int(a) for a in sys.argv[4:]))
