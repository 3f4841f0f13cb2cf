"""Per-frame stages on a scheduler (issue 56): workers against time.

Run: ``.venv/bin/python benchmarks/bm_pipeline.py [FRAMES]``. Meshes the standard crane scan
(frames 0, 2, ..., the bench's protocol) frame by frame (``perframe``'s stage,
:func:`fourd.geometry.frame_surface.frame_surfaces`) with each scheduler of
:func:`fourd.pipeline.map_frames`: ``sync`` in this process; ``processes`` with 1 and 2 local
worker processes; a local ``dask.distributed`` cluster on loopback with 1 and 2 single-threaded
workers (started before the clock). Prints seconds per frame, the speed-up over ``sync`` and
whether the meshes are the same as ``sync``'s. On a larger machine more workers can be listed
with ``--workers 1 2 4 8``.

Measured (2-core machine, nothing else running, 60 frames): sync 0.107 s/frame; processes 1
and 2 workers 0.140 and 0.100; distributed 1 and 2 workers 0.157 and 0.109; the same meshes
everywhere. No gain on 2 cores: one process already keeps 1.2 cores busy, and shipping a frame
costs about as much as meshing it (benchmarks/METHODS.md).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from fourd import synth
from fourd.bench.suite import PROTOCOL
from fourd.geometry.frame_surface import SurfaceSettings, frame_surfaces


def _timed(frames, scheduler, workers=None):
    started = time.perf_counter()
    if scheduler == "processes":
        from functools import partial

        from fourd.geometry.frame_surface import _surface_of
        from fourd.pipeline import map_frames

        meshes = map_frames(partial(_surface_of, SurfaceSettings()), frames, scheduler="processes", workers=workers)
    else:
        meshes, _ = frame_surfaces(frames, SurfaceSettings(), scheduler=scheduler, use_faces=False)
    return time.perf_counter() - started, meshes


def _same(a, b) -> bool:
    return all(np.array_equal(fa, fb) and np.allclose(va, vb, atol=1e-12) for (va, fa), (vb, fb) in zip(a, b, strict=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", nargs="?", type=int, default=20)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    truth = synth.scene("crane", frames=args.frames, start=0, step=2)
    frames = synth.scan(truth, resolution=256, seed=0, **PROTOCOL).frames
    print(f"crane, {len(frames)} frames, {np.mean([len(f.points) for f in frames]):.0f} points per frame, "
          f"{os.cpu_count()} cores")
    base, reference = _timed(frames, "sync")
    print(f"sync                      {base / len(frames):6.3f} s/frame")
    for workers in args.workers:
        seconds, meshes = _timed(frames, "processes", workers)
        print(f"processes, {workers} workers      {seconds / len(frames):6.3f} s/frame  x{base / seconds:4.2f}  "
              f"same: {_same(meshes, reference)}")
    from distributed import LocalCluster

    for workers in args.workers:
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=None) as cluster:
            seconds, meshes = _timed(frames, cluster.scheduler_address)
        print(f"distributed, {workers} workers    {seconds / len(frames):6.3f} s/frame  x{base / seconds:4.2f}  "
              f"same: {_same(meshes, reference)}")


if __name__ == "__main__":
    main()
