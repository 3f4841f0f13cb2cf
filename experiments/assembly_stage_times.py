"""Question: where does a whole `assembly` run's time go now, stage by stage (the frames'
meshes, the merges, the rest fit, the colour fit, the closing), on the bench's crane?

Setup: ``SCENE`` (crane by default: 20 frames every 2nd capture frame from 0, the bench's
standard scan) run through the steps of ``method.reconstruct_with_diagnostics`` with the
default options, each step timed with a wall clock. The merge workers run as in the method
(two processes on a 2-core machine).

Run: ``.venv/bin/python experiments/assembly_stage_times.py [SCENE]``. Nothing else should run
beside it.

Answer: see ``benchmarks/METHODS.md``, "Where crane's time goes, stage by stage (2026-12-04)".
"""

from __future__ import annotations

import sys
import time


def main() -> None:
    import fourd.bench.suite as suite
    from fourd import synth
    from fourd.cache import StageCache
    from fourd.geometry.hole_closing import close_small_holes
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.hierarchy import Block, assemble, merge_pool
    from fourd.methods.assembly.method import (
        _fit_colors,
        _frame_meshes,
        base_blocks,
        frame_pair_guides,
    )
    from fourd.methods.assembly.rest_fit import fit_rest

    scene = sys.argv[1] if len(sys.argv) > 1 else "crane"
    crane = {"frames": 20, "start": 0, "step": 2} if scene == "crane" else {}
    truth = synth.scene(scene, seed=0, **crane)
    seq = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL)
    options = Options()
    times: dict[str, float] = {}
    started = time.perf_counter()
    meshes, _ = _frame_meshes(seq, options, frames=slice(0, 1))
    times["first mesh"] = time.perf_counter() - started
    with merge_pool(options.merge_workers(len(meshes[0][0]))) as pool:
        t = time.perf_counter()
        others, _ = _frame_meshes(seq, options, pool, frames=slice(1, None))
        meshes = meshes + others
        times["other meshes"] = time.perf_counter() - t
        t = time.perf_counter()
        blocks = base_blocks(seq, meshes)
        block, _ = assemble(blocks, options, pool=pool, guides=frame_pair_guides(seq, options))
        times["merges"] = time.perf_counter() - t
    t = time.perf_counter()
    block = Block(block.faces, fit_rest(block.vertices, block.faces, block.observed, meshes,
                                        iterations=options.rest_fit, weight=options.rest_weight,
                                        cache=StageCache(None)), block.observed)
    times["rest fit"] = time.perf_counter() - t
    t = time.perf_counter()
    if options.color_fit:
        block = _fit_colors(seq, meshes, block, options)
    times["colour fit"] = time.perf_counter() - t
    t = time.perf_counter()
    if options.close_holes > 0:
        block = Block(*close_small_holes(*block, options.close_holes, options.close_smoothness,
                                         options.open_handles))
    times["closing"] = time.perf_counter() - t
    total = time.perf_counter() - started
    frames = len(seq)
    print(f"{scene}: {frames} frames, {block.vertices.shape[1]} vertices, {total:.1f} s, {total / frames:.2f} s/frame")
    for name, seconds in times.items():
        print(f"  {name:14s} {seconds:7.1f} s  {seconds / frames:5.2f} s/frame  {100 * seconds / total:4.0f}%")


if __name__ == "__main__":
    main()
