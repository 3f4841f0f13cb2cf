"""Issue 56, part 1: what makes ``kinematic`` lose crane's limbs at a sparse rig?

The whole crane capture (175 frames) is scanned by the standard rig (three cameras framing the
whole capture volume) at ``RESOLUTION`` rays per side (160: about 2,600 points per frame, the
issue's sparse rig), and ``kinematic`` runs on its first ``FRAMES`` frames with one suspect
changed at a time: the large-motion registration, the template's resolution, the data ball
``epsilon``, the rigid prediction, the sliding's iterations. Correspondence mean / last and
Chamfer, fractions of the 40 frames' truth diagonal; per-frame correspondence every 5 frames.

Answer (2,791 points per frame; correspondence mean / last, Chamfer): defaults at the time (a
10,000-vertex template) 0.0350 / 0.0833, 0.0074; large_motion=false 0.0364 / 0.0852; epsilon
doubled 0.0300 / 0.0699; rigid_guess=false 0.0310 / 0.0558; 8 iterations 0.0393 / 0.1000;
template 5,000 / 3,000 / 2,000 vertices 0.0188 / 0.0255, 0.0156 / 0.0160, 0.0137 / 0.0170. The
template's density against the data's is the cause; kinematic now caps the urshape at one vertex
per point of the median frame (``urshape.template_size``): "default" then gives 0.0179 / 0.0189,
Chamfer 0.0047.

Run from the repository root (about 10 minutes on 2 cores)::

    .venv/bin/python experiments/sparse_limbs.py
"""

from __future__ import annotations

import sys
import time

import numpy as np

from fourd import synth
from fourd.methods import method_options, reconstruct
from fourd.metrics import evaluate

FRAMES = 40
RESOLUTION = 160
VARIANTS = {
    "default": {},
    "large_motion=false": {"large_motion": "false"},
    "template_vertices=5000": {"template_vertices": "5000"},
    "template_vertices=3000": {"template_vertices": "3000"},
    "template_vertices=2000": {"template_vertices": "2000"},
    "epsilon x2 (0.02)": {"epsilon": "0.02"},
    "rigid_guess=false": {"rigid_guess": "false"},
    "iterations=8": {"iterations": "8"},
}


def main(names) -> None:
    truth = synth.scene("crane", frames=175, step=1)
    started = time.perf_counter()
    scans = synth.scan(truth, resolution=RESOLUTION, seed=0).select(0, FRAMES)
    truth = truth.select(0, FRAMES)
    print(f"scanned in {time.perf_counter() - started:.0f} s: "
          f"{np.mean([len(f) for f in scans]):.0f} points per frame (mean), diagonal {truth.diagonal():.3f}")
    for name in names or VARIANTS:
        options = method_options("kinematic", VARIANTS[name])
        started = time.perf_counter()
        result = reconstruct(scans, "kinematic", options)
        seconds = time.perf_counter() - started
        report = evaluate(result, truth, samples=20000)
        curve = report["per_frame"]["correspondence"]
        print(f"{name:24s} corr {report['correspondence_mean']:.4f} / {report['correspondence_last']:.4f}, "
              f"Chamfer {report['chamfer']:.4f}, {seconds / FRAMES:.2f} s/frame; every 5th frame: "
              + " ".join(f"{c:.3f}" for c in curve[::5]), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
