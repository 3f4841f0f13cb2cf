"""Question: does `surfels` stop sliding along a featureless surface when the video's anchors
pull its surfels (`video_anchors`, `anchor_weight`)? The issue's waving-sheet target is
correspondence 0.03 / 0.04; geometry alone gives 0.136 / 0.265 (the sheet slides with the wave).

    PYTHONPATH=src python experiments/surfels_video_anchors.py SCENE FRAMES RESOLUTION [WEIGHT ...]

Runs `surfels` on the scene's FRAMES frames (the first `USE` of them, all by default)
scanned as the bench does (3 cameras,
noise, outliers) at RESOLUTION rays per side, in cloth with the rig's video, once without
anchors and once per anchor weight; prints Chamfer / completeness-95 / correspondence mean /
last and seconds per frame (`fourd.metrics.evaluate`, 20k samples). With `CHECK=1` it first
prints, per frame pair, how far the anchors' targets lie from where the truth's vertex nearest
each source went (median / 90th / 99th percentile, in point spacings; the truth's own vertex
spacing bounds what this can resolve); `CHECK=only` stops there. `SET=linked_tangential=0,...`
sets other options of every run; `BASELINE=0` leaves out the run without anchors;
`NEIGHBOURS=48` gives the colours' guide's Lucas-Kanade patches that many surfels (24 by
default; the patch radius is `color_radius`); `BLENDED=1` reads the guide's colour fields
blended across their points (`surfels_guide_accuracy.BlendedField`).

Answer: see benchmarks/METHODS.md, "The video's anchors in `surfels`".
"""

import ast
import functools
import os
import sys
import time

import numpy as np
from scipy.spatial import cKDTree

import fourd
from fourd.appearance.photometric import photometric_shift
from fourd.appearance.surface_color import FIELD_POINTS_PER_READ
from fourd.bench.suite import PROTOCOL
from fourd.cache import NO_CACHE
from fourd.geometry.neighbors import point_spacing
from fourd.methods.surfels import Options, color_guide, reconstruct
from fourd.methods.surfels.anchors import with_video_anchors
from fourd.methods.surfels.pipeline import prepare_frames
from fourd.metrics.scores import evaluate


def check_anchors(truth, scans) -> None:
    """Each pair's anchors against the truth's motion (module docstring)."""
    spacing = point_spacing(scans.frames[0].points)
    frames, _ = prepare_frames(scans.frames, spacing, Options(), NO_CACHE)
    frames = with_video_anchors(frames, scans.times, scans.video, scans.names)
    for t, pair in enumerate(frame.forward for frame in frames[:-1]):
        _, nearest = cKDTree(truth.vertices[t]).query(pair.source)
        error = np.linalg.norm(pair.target - truth.vertices[t + 1][nearest], axis=1) / spacing
        print(f"pair {t}: {len(error)} anchors, off by " + " / ".join(
            f"{v:.2f}" for v in np.percentile(error, [50, 90, 99])) + " spacings", flush=True)


def main(scene: str, frames: int, resolution: int, weights: list[float]) -> None:
    truth = fourd.synth.scene(scene, frames=frames)
    scans = fourd.synth.scan(
        truth, **{**PROTOCOL, "resolution": resolution, "appearance": "cloth", "video": True}
    )
    if os.environ.get("NEIGHBOURS"):
        color_guide.photometric_shift = functools.partial(
            photometric_shift, neighbours=int(os.environ["NEIGHBOURS"])
        )
    if os.environ.get("BLENDED"):
        from surfels_guide_accuracy import BlendedField  # this folder's

        def blended(points, normals, colors, reads):
            stride = max(1, len(points) // (FIELD_POINTS_PER_READ * max(1, int(reads))))
            return BlendedField(points[::stride], normals[::stride], colors[::stride])

        color_guide.field_for_reads = blended
    use = int(os.environ.get("USE", frames))
    if use < frames:
        truth = fourd.AnimatedMesh(truth.faces, truth.vertices[:use], truth.times[:use])
        scans = fourd.PointCloudSequence(
            scans.frames[:use], scans.names[:use], scans.video.select(slice(0, use))
        )
        frames = use
    if os.environ.get("CHECK"):
        check_anchors(truth, scans)
        if os.environ["CHECK"] == "only":
            return
    settings = dict(
        (key, ast.literal_eval(value))
        for key, value in (item.split("=") for item in os.environ.get("SET", "").split(",") if item)
    )
    baseline = [] if os.environ.get("BASELINE") == "0" else [None]
    for weight in [*baseline, *weights]:
        options = Options(
            **{"video_anchors": weight is not None, "anchor_weight": weight or 0.0, **settings}
        )
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
