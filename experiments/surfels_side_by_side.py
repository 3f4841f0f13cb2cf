"""Question (issue 50, speed): a ``surfels`` merge runs on one core most of the time (scipy's
sparse products and the Python between the kernels are single-threaded). Do two merges of one
level, or two frames of the per-frame stages, run side by side on a 2-core machine, give the
same result faster, and at what memory?

Run from the repository root::

    PYTHONPATH=src .venv/bin/python experiments/surfels_side_by_side.py levels
    PYTHONPATH=src .venv/bin/python experiments/surfels_side_by_side.py capture
    PYTHONPATH=src .venv/bin/python experiments/surfels_side_by_side.py pair serial
    PYTHONPATH=src .venv/bin/python experiments/surfels_side_by_side.py pair threads
    PYTHONPATH=src .venv/bin/python experiments/surfels_side_by_side.py pair processes
    PYTHONPATH=src .venv/bin/python experiments/surfels_side_by_side.py frames

``levels`` times every merge of the bench's crane (20 frames; with ``Options(workers=1)``);
``capture`` keeps the inputs of its first two merges and of the two merges of level 3;
``pair MODE`` reruns each pair one after another, in two threads or in two spawned processes
(one thread per pool) and prints the time, the peak resident memory and whether the results
equal the first ``serial`` run's; ``frames`` times the preprocessing and the seed regions of
crane's 20 frames with one and two worker threads.

Answer (2-core AMD EPYC, nothing else running, 2026-12-07, at b104bbd for the merges and at
3f67f94 for ``frames``):

- ``levels``: 235 s in all; level 1 (10 merges of 1 + 1 frames) 55 s, level 2 (5 of 2 + 2)
  42 s, level 3 (2 of 4 + 4) 24 s, level 4 (8 + 8) 27 s, level 5 (16 + 4) 37 s.
- ``pair``: level 1's pair 10.6 / 10.3 s one after another, 6.5 s in threads, 6.5 s in
  processes; level 3's 24.5 / 23.0 s, 15.2 s, 14.9 s; identical results every way. Level 3's
  pair alone in a fresh process (its inputs loaded first, 147 MB) peaked at 838 MB one after
  another and 1,352 MB in threads, 1,265 MB in threads with one malloc arena (``mallopt``
  ``M_ARENA_MAX`` 1): the two working sets, not the allocator.
- ``frames``: preprocessing 6.45 / 6.37 s with one thread, 3.83 / 3.81 s with two; seeds 6.24 /
  6.01 s against 3.85 / 4.07 s; the same seeds.

So threads (no start-up, no pickling, one copy of the frames): ``Options.workers`` (0: one per
core, at most 2). ``fourd bench --methods surfels --scenes crane``: 12.68 -> 10.32 s/frame, peak
1,879 -> 2,461 MB, every score the same (benchmarks/METHODS.md, "Speed: the merges side by
side").
"""

from __future__ import annotations

import multiprocessing
import pickle
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import numpy as np

PAIRS = Path("/tmp/surfels_side_by_side_pairs.pkl")
REFERENCE = Path("/tmp/surfels_side_by_side_reference.pkl")
#: (left.start, right.stop) of the merges ``capture`` keeps: level 1's first two, level 3's two.
KEPT = [(0, 2), (2, 4), (0, 8), (8, 16)]


def _crane():
    from fourd.bench.suite import BenchScene, scan_scene

    return scan_scene(BenchScene("crane", frames=20, options={"start": 0, "step": 2}))[1]


def levels() -> None:
    import fourd
    import fourd.methods.surfels.assembly as assembly

    scans = _crane()
    merge = assembly.merge

    def timed(left, right, frames, schedule, **kwargs):
        started = time.perf_counter()
        model = merge(left, right, frames, schedule, **kwargs)
        print(
            f"frames {left.start}-{left.stop - 1} + {right.start}-{right.stop - 1}: "
            f"{time.perf_counter() - started:.1f} s",
            flush=True,
        )
        return model

    assembly.merge = timed
    started = time.perf_counter()
    fourd.reconstruct(scans, method="surfels", workers=1)
    print(f"in all {time.perf_counter() - started:.0f} s")


class _Enough(Exception):
    pass


def capture_merges(ranges: list, path: Path) -> None:
    """Pickle into ``path`` the inputs (left, right, frames, schedule) of the bench's crane
    merges whose ``(left.start, right.stop)`` are in ``ranges``, stopping the run there."""
    import fourd
    import fourd.methods.surfels.assembly as assembly

    scans = _crane()
    merge, kept = assembly.merge, []

    def keep(left, right, frames, schedule, **kwargs):
        if (left.start, right.stop) in ranges:
            kept.append((left, right, frames, schedule))
            if len(kept) == len(ranges):
                path.write_bytes(pickle.dumps(kept))
                raise _Enough
        return merge(left, right, frames, schedule, **kwargs)

    assembly.merge = keep
    try:
        fourd.reconstruct(scans, method="surfels", workers=1)
    except _Enough:
        print(f"{len(kept)} merges kept in {path}")
    finally:
        assembly.merge = merge


def capture() -> None:
    capture_merges(KEPT, PAIRS)


def pair(mode: str) -> None:
    from fourd.methods.surfels.assembly import merge
    from fourd.pipeline.worker_threads import threads_per_worker

    kept = pickle.loads(PAIRS.read_bytes())
    reference = pickle.loads(REFERENCE.read_bytes()) if REFERENCE.exists() else {}
    for name, jobs in (("level 1", kept[:2]), ("level 3", kept[2:])):
        started = time.perf_counter()
        if mode == "serial":
            out = [merge(*job) for job in jobs]
        elif mode == "threads":
            with ThreadPoolExecutor(2) as pool:
                out = list(pool.map(lambda job: merge(*job), jobs))
        else:
            context = multiprocessing.get_context("spawn")
            with threads_per_worker(2), ProcessPoolExecutor(2, mp_context=context) as pool:
                out = [f.result() for f in [pool.submit(merge, *job) for job in jobs]]
        seconds = time.perf_counter() - started
        if mode == "serial" and name not in reference:
            reference[name] = out
            REFERENCE.write_bytes(pickle.dumps(reference))
        same = all(
            np.array_equal(a.state.positions, b.state.positions)
            and np.array_equal(a.state.normals, b.state.normals)
            for a, b in zip(out, reference[name], strict=True)
        )
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
        print(f"{mode} {name}: {seconds:.1f} s, peak {peak} MB, identical {same}", flush=True)


def frames() -> None:
    from fourd.cache import NO_CACHE
    from fourd.geometry.neighbors import point_spacing
    from fourd.methods.surfels import Options, pipeline

    scans = _crane()
    spacing = point_spacing(scans.frames[0].points)
    first = None
    for workers in (1, 2, 1, 2):
        options = Options(workers=workers)
        started = time.perf_counter()
        prepared, _ = pipeline.prepare_frames(scans.frames, spacing, options, NO_CACHE)
        middle = time.perf_counter()
        sampling = options.sampling * spacing
        schedule = pipeline.assembly_schedule(options, spacing, sampling)
        seeds = pipeline.seed_models(prepared, range(len(prepared)), sampling, schedule, options)
        end = time.perf_counter()
        first = first or seeds
        same = all(
            np.array_equal(a.state.positions, b.state.positions)
            for a, b in zip(first, seeds, strict=True)
        )
        print(
            f"workers {workers}: preprocessing {middle - started:.2f} s, seeds "
            f"{end - middle:.2f} s, identical {same}",
            flush=True,
        )


if __name__ == "__main__":
    command = sys.argv[1] if len(sys.argv) > 1 else "levels"
    if command == "pair":
        pair(sys.argv[2] if len(sys.argv) > 2 else "serial")
    else:
        {"levels": levels, "capture": capture, "frames": frames}[command]()
