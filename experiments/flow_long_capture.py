"""Issue 56, windows for ``flow``: does ``flow``, streamed in windows, keep its peak memory and
its time per frame as the capture grows?

The capture of ``experiments/long_capture.py`` (the crane played ping-pong, three virtual depth
cameras at 700 rays per side, about 50,000 points per frame; :func:`fourd.synth.long_capture`),
reconstructed by ``flow`` streamed (:func:`fourd.methods.flow.reconstruct_streamed`, windows of
20 frames sharing 4, default options otherwise), the meshes written frame by frame to a
``.npz``. Each length runs in a fresh process (peak resident memory from ``getrusage``; the
time includes scanning, about 0.23 s per frame). Then each result is scored against the truth
on every 10th frame (Chamfer and completeness-95, fractions of the crane's diagonal).

Answer (2-core development machine, nothing else running; the score processes afterwards):

| frames | windows | s/frame | peak MB | mass error | Chamfer / completeness-95 (every 10th frame) | closed |
|---|---|---|---|---|---|---|
| 40 | 3 | 3.83 | 972 | 2.9% | 0.0029 / 0.0060 | 100% |
| 200 | 13 | 3.24 | 999 | 2.7% | 0.0020 / 0.0043 | 100% |

Peak memory 1.03 times at five times the length: it is one window's solve. The time per frame
falls with the length, since the last window of a short capture shares most of its frames
(40 frames: windows 0-19, 16-35, 20-39). The Chamfer rows score different poses.

Run from the repository root (about 10 minutes on 2 cores)::

    .venv/bin/python experiments/flow_long_capture.py            # 40 and 200 frames
    .venv/bin/python experiments/flow_long_capture.py run 40     # one length
    .venv/bin/python experiments/flow_long_capture.py score 40   # score a finished run
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FRAMES = (40, 200)
RESOLUTION = 700
WINDOW = 20
OUT = Path(tempfile.gettempdir()) / "fourd-flow-long-capture"


def run(frames: int) -> dict:
    from fourd.methods.flow import Options, reconstruct_streamed
    from fourd.synth.whole_capture import long_capture

    OUT.mkdir(exist_ok=True)
    capture = long_capture(frames, resolution=RESOLUTION)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    started = time.perf_counter()
    summary = reconstruct_streamed(capture.source, OUT / f"{frames}.npz", Options(window=WINDOW))
    seconds = time.perf_counter() - started
    row = {
        "frames": frames,
        "windows": summary.windows,
        "s_per_frame": seconds / frames,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "before_mb": before,
        "mass_error": summary.mass_error,
    }
    print(json.dumps(row), flush=True)
    return row


def score(frames: int) -> dict:
    from fourd.animation import AnimatedMesh, MeshSequence
    from fourd.io.results import load_result
    from fourd.metrics import evaluate
    from fourd.synth.whole_capture import long_capture

    capture = long_capture(frames, resolution=RESOLUTION)
    result = load_result(OUT / f"{frames}.npz")
    every = np.arange(0, frames, 10)
    sub_result = MeshSequence(tuple(result.meshes[i] for i in every), every.astype(float))
    truth = capture.truth
    sub_truth = AnimatedMesh(
        truth.faces, truth.vertices[capture.index[every]], times=every.astype(float)
    )
    scores = evaluate(sub_result, sub_truth, samples=30000)
    row = {
        "frames": frames,
        "chamfer": scores["chamfer"],
        "completeness_95": scores.get("completeness_95"),
        "closed_manifold": scores.get("closed_manifold"),
    }
    print(json.dumps(row), flush=True)
    return row


if __name__ == "__main__":
    if len(sys.argv) == 3:
        (run if sys.argv[1] == "run" else score)(int(sys.argv[2]))
    else:
        for count in FRAMES:
            subprocess.run([sys.executable, __file__, "run", str(count)], check=True)
        for count in FRAMES:
            subprocess.run([sys.executable, __file__, "score", str(count)], check=True)
