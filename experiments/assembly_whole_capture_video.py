"""Question: does `assembly`'s chain stop drifting over the whole crane capture when the input
has colour and video (the video's anchors, ``anchors="video"``, and the colour fit,
``color_fit``), where geometry alone climbs a staircase at every fast motion?

Setup: all 175 crane frames, the bench's whole-capture rig at 256 rays a side (``crane-full-mid``'s
density, about 6,700 points a frame), printed cloth and the rig's 3-camera video at 256
pixels; `assembly` with the options given.
Correspondence mean / last and every 25th frame, Chamfer (20,000 samples), seconds.

Run: ``.venv/bin/python experiments/assembly_whole_capture_video.py [KEY=VALUE,KEY=VALUE ...]``
(each argument one run with those options; none: the default, the video's anchors with the
colour fit, and geometry alone; about 7 minutes a run).

Answer (2026-12-02; correspondence mean / last, Chamfer): geometry alone 0.0200 / 0.0353,
0.0041; video anchors without the colour fit 0.0331 / 0.0560, 0.0044; the anchors and the
colour fit (the default then) 0.0251 / 0.0481, 0.0059; the colour fit alone (``anchors=geometry``) 0.0105 /
0.0203, 0.0039. The video's anchors hurt at the whole-volume rig (the performer a few pixels
wide), the colours halve the chain's drift; see ``benchmarks/METHODS.md``, `assembly`, "The whole crane
capture at the sparse rig". Later the same day: the anchors at ``guide_pull`` 1 (a wrong one
then only joins the anchors where the alignment agrees with it) 0.0265 / 0.0450 without the
colour fit, 0.0184 / 0.0360 with it: still worse than the fit alone, so ``auto`` leaves the
anchors out while the colour fit runs (METHODS.md, "`auto` leaves the video's anchors out").
"""

from __future__ import annotations

import sys
import time

from fourd import synth
from fourd.bench.suite import PROTOCOL
from fourd.methods import reconstruct
from fourd.metrics import evaluate


def main(runs) -> None:
    truth = synth.scene("crane", frames=175, seed=0, start=0, step=1)
    scans = synth.scan(truth, resolution=256, seed=0, appearance="cloth", video=True, **PROTOCOL)
    for label, values in runs:
        started = time.perf_counter()
        result = reconstruct(scans, "assembly", **values)
        seconds = time.perf_counter() - started
        scores = evaluate(result, truth, samples=20000)
        curve = scores["per_frame"]["correspondence"]
        print(f"{label}: correspondence {scores['correspondence_mean']:.4f} / {scores['correspondence_last']:.4f}, "
              f"Chamfer {scores['chamfer']:.4f}, {seconds / len(truth.vertices):.2f} s/frame; every 25th frame "
              + " ".join(f"{curve[t]:.4f}" for t in range(0, len(curve), 25)), flush=True)


if __name__ == "__main__":
    if len(sys.argv) > 1:  # option values as strings, converted by the method's options
        main([(arg, dict(pair.split("=", 1) for pair in arg.split(","))) for arg in sys.argv[1:]])
    else:
        main([("default (colour fit)", {}), ("video anchors and colour fit", {"anchors": "video"}),
              ("geometry alone", {"anchors": "geometry", "color_fit": "false"})])
