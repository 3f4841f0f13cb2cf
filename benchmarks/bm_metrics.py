"""Time :func:`fourd.metrics.evaluate` on the crane truth (20 frames, 60,000 samples).

Run: ``.venv/bin/python benchmarks/bm_metrics.py``. Prints the wall time of the floor (the truth
against itself: near queries) and of a frame-0 copy held still (far queries: the slow case).
"""

from __future__ import annotations

import time

import numpy as np

from fourd import AnimatedMesh, synth
from fourd.metrics import evaluate, metric_floor


def main() -> None:
    truth = synth.scene("crane")
    started = time.perf_counter()
    floor = metric_floor(truth)
    print(f"floor of crane ({truth.frame_count} frames): {time.perf_counter() - started:.1f} s, "
          f"Chamfer {floor['chamfer']:.4f}")
    still = AnimatedMesh(truth.faces, np.repeat(truth.vertices[:1], truth.frame_count, axis=0))
    started = time.perf_counter()
    report = evaluate(still, truth)
    print(f"frame 0 held still: {time.perf_counter() - started:.1f} s, Chamfer {report['chamfer']:.4f}, "
          f"correspondence last {report['correspondence_last']:.4f}")


if __name__ == "__main__":
    main()
