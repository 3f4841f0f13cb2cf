"""Issue 56, the 1,000-frame target's question at a smaller scale: with the 4D fit in windows,
does ``kinematic``'s peak memory stay flat as the sequence grows?

The whole crane capture scanned at the dense rig (400 rays per side, 16,505 points per frame),
``kinematic`` with ``window=20`` on its first 40 and its first 160 frames, each in a fresh
process (peak resident memory from ``getrusage``; "after loading": the scan of all 175 frames
in memory before the method starts).

Answer (2-core development machine, nothing else running): 40 frames 0.42 s/frame, peak 617
MB; 160 frames 0.49 s/frame, peak 1,079 MB (349 MB after scanning, both). Four times the
frames take 2.7 times the memory above the scan, although each window's fit is the same size:
the prepared frames (points and normals of every frame), the result's vertex positions and the
sliding's per-frame state are held for the whole sequence; and the time per frame grows by 17%.
Bounding memory by the window needs frames read lazily and the result written frame by frame,
not only the windows.

Run from the repository root (about 5 minutes on 2 cores)::

    .venv/bin/python experiments/window_memory.py
"""

from __future__ import annotations

import resource
import subprocess
import sys
import time

FRAMES = (40, 160)


def run(frames: int) -> None:
    from fourd import synth
    from fourd.methods import method_options, reconstruct

    truth = synth.scene("crane", frames=175, step=1)
    scans = synth.scan(truth, resolution=400, seed=0)
    del truth
    loaded = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    scans = scans.select(0, frames)
    started = time.perf_counter()
    reconstruct(scans, "kinematic", method_options("kinematic", {"window": "20"}))
    seconds = time.perf_counter() - started
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{frames} frames, window 20: {seconds / frames:.2f} s/frame, peak {peak:.0f} MB "
          f"({loaded:.0f} MB after loading the scan)", flush=True)


if __name__ == "__main__":
    if len(sys.argv) > 1:
        run(int(sys.argv[1]))
    else:
        for count in FRAMES:
            subprocess.run([sys.executable, __file__, str(count)], check=True)
