"""Question: does `surfels` stop sliding along a featureless surface when the video's anchors
pull its surfels (`video_anchors`, `anchor_weight`)? The issue's waving-sheet target is
correspondence 0.03 / 0.04; geometry alone gives 0.136 / 0.265 (the sheet slides with the wave).

    PYTHONPATH=src python experiments/surfels_video_anchors.py SCENE FRAMES RESOLUTION [WEIGHT ...]

Runs `surfels` on the scene's FRAMES frames (the first `USE` of them, all by default)
scanned as the bench does (3 cameras,
noise, outliers) at RESOLUTION rays per side, in cloth with the rig's video, once without
anchors and once per anchor weight; prints Chamfer / completeness-95 / correspondence mean /
last and seconds per frame (`fourd.metrics.evaluate`, 20k samples).

Answer: see benchmarks/METHODS.md, "The video's anchors in `surfels`".
"""

import os
import sys
import time

import fourd
from fourd.bench.suite import PROTOCOL
from fourd.methods.surfels import Options, reconstruct
from fourd.metrics.scores import evaluate


def main(scene: str, frames: int, resolution: int, weights: list[float]) -> None:
    truth = fourd.synth.scene(scene, frames=frames)
    scans = fourd.synth.scan(
        truth, **{**PROTOCOL, "resolution": resolution, "appearance": "cloth", "video": True}
    )
    use = int(os.environ.get("USE", frames))
    if use < frames:
        truth = fourd.AnimatedMesh(truth.faces, truth.vertices[:use], truth.times[:use])
        scans = fourd.PointCloudSequence(
            scans.frames[:use], scans.names[:use], scans.video.select(slice(0, use))
        )
        frames = use
    for weight in [None, *weights]:
        options = Options(video_anchors=weight is not None, anchor_weight=weight or 0.0)
        started = time.perf_counter()
        result = reconstruct(scans, options)
        seconds = (time.perf_counter() - started) / frames
        report = evaluate(result, truth, samples=20000)
        print(
            f"anchors {weight}: {report['chamfer']:.4f} / {report['completeness_95']:.4f} / "
            f"{report['correspondence_mean']:.4f} / {report['correspondence_last']:.4f}, "
            f"{seconds:.2f} s/frame",
            flush=True,
        )
        frame = report["per_frame"]
        for name in ("accuracy_95", "completeness_95", "correspondence"):
            print(f"  {name}: " + " ".join(f"{v:.4f}" for v in frame[name]), flush=True)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), [float(w) for w in sys.argv[4:]] or [1.0])
