"""Question: how much of a clean clone's test time is numba compiling, and which kernels cost
the most to compile?

Setup: the work of ``tests/appearance/test_anchor_guide.py::test_exact_anchors_cut_the_drift_of_
the_tracking`` without its anchors (bending-arm, 6 frames, scanned at 96 with the cloth
appearance and video at 64, ``kinematic`` without the colour guide or video anchors, scored by
``fourd.metrics.evaluate``), with numba's compile events recorded per kernel. Run it once with
the cache cold (delete the ``*.nbi`` and ``*.nbc`` files under ``src/``, as in a fresh clone)
and once warm. A kernel's time includes the kernels compiled inside it, so the times overlap.

Run: ``.venv/bin/python experiments/numba_compile_times.py``

Answer (2-core machine, clean clone at ae6d58c): cold 120 s in all (190 s of compile events,
nested ones counted in each), warm about 14 s. The slowest to compile:
``kinematic.mpu_fit._fit_cells`` 49 s (``_fit_lowvariate`` 11 s, ``_local_error`` 5 s and
``_fit_generic`` 3 s inside it), ``geometry.rotations._best_rotations`` 11 s,
``geometry.normals._pca_kernel`` 7.5 s, ``kinematic.mpu_eval._evaluate_slice`` 6.6 s,
``kinematic.framesurface._imls`` 6 s. The test itself: 129 s cold, 14 s warm (this script warm: 9.6 s, no compile). The whole suite
in a clean clone took 20 min 22 s against 17 min 32 s with the cache warm (browser tests
skipped there). Two trials in a scratch clone, cache cold: without ``inline="always"`` in the MPU
fit, the MPU evaluation and the rotations, ``_fit_cells`` still took 52 s; without
``parallel=True`` it took 29 s (the parallel loop's compilation is about 23 s, but the fit then
runs serially). A third (2026-11-30, only the MPU fit's cache deleted): the loop's body moved
into its own kernel, the parallel loop holding only the call: ``_fit_cells`` 60.0 s, the body
44.7 s of it, against 56.6 s as it is. The body itself is the cost, not the parallel loop around
it; not kept.
"""

from __future__ import annotations

import collections
import time


def main() -> None:
    from numba.core import event

    times: dict[str, float] = collections.defaultdict(float)
    started: dict[int, float] = {}

    class Recorder(event.Listener):
        def on_start(self, ev):
            started[id(ev.data["dispatcher"])] = time.perf_counter()

        def on_end(self, ev):
            dispatcher = ev.data["dispatcher"]
            name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
            times[name] += time.perf_counter() - started.pop(id(dispatcher), time.perf_counter())

    event.register("numba:compile", Recorder())
    begin = time.perf_counter()
    from fourd import synth
    from fourd.methods import kinematic
    from fourd.metrics import evaluate

    truth = synth.scene("bending-arm", frames=6)
    scans = synth.scan(truth, resolution=96, seed=0, appearance="cloth", video=True, video_resolution=64)
    result = kinematic.reconstruct(scans, kinematic.Options(color_guide=False, video_anchors=False))
    evaluate(result, truth, samples=5000)
    total = time.perf_counter() - begin
    print(f"total {total:.1f} s, compile events {sum(times.values()):.1f} s in {len(times)} kernels")
    for name, seconds in sorted(times.items(), key=lambda item: -item[1])[:15]:
        print(f"{seconds:6.1f} s  {name}")


if __name__ == "__main__":
    main()
