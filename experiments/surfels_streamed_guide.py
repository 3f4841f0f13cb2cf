"""Question: does the colours' guide hold `surfels`' streamed run (window by window) as it holds
the run in memory, and does carrying the mesh surfels' reference colours from the first window
matter, against each window taking its own (chained from window to window)?

    PYTHONPATH=src python experiments/surfels_streamed_guide.py [SCENE FRAMES RESOLUTION USE WINDOW]

(`ONLY=TEXT`: only the runs whose name has TEXT.)

Runs `surfels` on the first USE of the scene's FRAMES frames at RESOLUTION rays per side, in
cloth with the rig's video, the video's anchors off: in memory without and with the guide,
then streamed in windows of WINDOW frames without the guide, with it, and with it but the
reference colours not carried (each window's mesh surfels take theirs from the window's first
frame). Prints Chamfer / completeness-95 / correspondence mean / last (`fourd.metrics.evaluate`,
20k samples), the per-frame correspondence and seconds per frame.

Answer (waving-sheet 20 64 10 4, then 20 frames; benchmarks/METHODS.md, "The colours' guide",
"Streamed"): the guide holds the streamed sheet as in memory, correspondence mean / last 0.0776 /
0.1538 without -> 0.0035 / 0.0053 with it (in memory 0.0878 / 0.1656 -> 0.0051 / 0.0089).
Carrying the reference: the same over 10 frames, 0.0068 against 0.0080 chained in the last of
20 frames. Bending-arm (`ONLY=streamed ... bending-arm 20 128 20 8`): 0.0255 / 0.0547 without
the guide, 0.0032 / 0.0047 with it, 0.0035 / 0.0049 chained.
"""

import os
import sys
import time

from surfels_guide_accuracy import cloth_video_scene, print_scores  # this folder's

import fourd
from fourd.methods.surfels import stream


def main(scene: str, frames: int, resolution: int, use: int, window: int) -> None:
    truth, scans = cloth_video_scene(scene, frames, resolution, use)
    carried = stream._mesh_reference
    runs = [
        ("in memory, no guide", dict(color_guide=False), carried),
        ("in memory, guide", {}, carried),
        ("streamed, no guide", dict(window=window, color_guide=False), carried),
        ("streamed, guide", dict(window=window), carried),
        ("streamed, guide chained", dict(window=window), lambda *args: None),
    ]
    only = os.environ.get("ONLY")
    for name, settings, reference in runs:
        if only and only not in name:
            continue
        stream._mesh_reference = reference
        started = time.perf_counter()
        result = fourd.reconstruct(scans, method="surfels", video_anchors=False, **settings)
        seconds = (time.perf_counter() - started) / use
        print_scores(name, result, truth, seconds)
    stream._mesh_reference = carried


if __name__ == "__main__":
    args = sys.argv[1:] or ["waving-sheet", "20", "64", "10", "4"]
    main(args[0], int(args[1]), int(args[2]), int(args[3]), int(args[4]))
