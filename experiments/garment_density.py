"""Question: how does `garment` degrade with the scan's density (issue 56: "the same for
surfels, assembly and garment as they land")? Does it lose a sleeve or an opening on a sparse
rig, as `kinematic` lost the crane's limbs at 2,600 points per frame?

    python experiments/garment_density.py [SCENE] [RESOLUTIONS...]

SCENE: a garment bench scene (``tshirt-cloth-video`` by default); RESOLUTIONS: rays per camera
side (default 128 160 256 400; the bench's standard scan is 256). Each density is scanned with
the bench's protocol and video, and `garment` runs with its bench options and the scene's own
photo; printed per density: points per frame, correspondence mean / last, Chamfer,
completeness-95 (60,000 samples, as the bench), the anchors' largest distance from the true
hem centres (fractions of the diagonal) and seconds per frame.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fourd import synth
from fourd.bench.suite import GARMENT_BENCH_SCENES, GARMENT_HELD_OUT_SCENES, PROTOCOL
from fourd.geometry.boundary_loops import boundary_loops
from fourd.methods import garment
from fourd.methods.garment import pipeline
from fourd.metrics import evaluate
from fourd.synth.garments import pattern_outline
from fourd.synth.write import write_pattern_photo

BOUNDARIES = {"tshirt": 4, "dress": 2}


def main(label: str, resolutions: list[int]) -> None:
    scene = next(s for s in GARMENT_BENCH_SCENES + GARMENT_HELD_OUT_SCENES if s.key == label)
    truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
    photo = write_pattern_photo(pattern_outline(scene.name, with_openings=True), Path(tempfile.mkdtemp()))
    hems = boundary_loops(truth.faces, truth.vertex_count)
    for resolution in resolutions:
        scans = synth.scan(truth, resolution=resolution, seed=0, appearance=scene.appearance,
                           video=scene.video, **{**PROTOCOL, **scene.scan})
        points = int(np.median([len(f.points) for f in scans.frames]))
        tracks = []
        track = pipeline.track_boundary

        def keep(*args, _track=track, _tracks=tracks, **kwargs):
            result = _track(*args, **kwargs)
            _tracks.append(result)
            return result

        pipeline.track_boundary = keep
        started = time.perf_counter()
        try:
            result = garment.reconstruct(scans, garment.Options(boundaries=BOUNDARIES[scene.name], photo=str(photo)))
        finally:
            pipeline.track_boundary = track
        seconds = (time.perf_counter() - started) / len(scans)
        r = evaluate(result, truth, samples=60000, seed=0)
        # each tracked opening against the truth's hem loop nearest its first centre (as
        # experiments/garment_openings.py)
        off = []
        for t_track in tracks:
            first = t_track.ellipse(0).center
            hem = hems[int(np.argmin([np.linalg.norm(truth.vertices[0][h].mean(axis=0) - first) for h in hems]))]
            off.append(max(np.linalg.norm(t_track.ellipse(t).center - truth.vertices[t][hem].mean(axis=0))
                           for t in range(len(scans))) / truth.diagonal())
        anchors = f", openings' centres off by at most {' / '.join(f'{o:.4f}' for o in off)}"
        print(f"{label} at {resolution} rays ({points} points a frame): correspondence "
              f"{r['correspondence_mean']:.4f} / {r['correspondence_last']:.4f}, Chamfer {r['chamfer']:.4f}, "
              f"completeness-95 {r['completeness_95']:.4f}{anchors}, {seconds:.2f} s/frame", flush=True)


if __name__ == "__main__":
    arguments = sys.argv[1:]
    name = arguments.pop(0) if arguments and not arguments[0].isdigit() else "tshirt-cloth-video"
    main(name, [int(a) for a in arguments] or [128, 160, 256, 400])
