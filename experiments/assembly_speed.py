"""Question: how long does `assembly` take per frame on full-size frames, merges alone, and
what do the merge workers buy?

Setup: crane at the bench's standard scan (`fourd bench`'s protocol), ``FRAMES`` frames every
2nd capture frame from 0; each frame meshed as the method does (not timed), then
``hierarchy.assemble`` timed alone with ``WORKERS`` (0: the default, one per core for frames
this size).

Run: ``.venv/bin/python experiments/assembly_speed.py [FRAMES [WORKERS]]`` (4 and 0 by
default). Nothing else should run beside it: two jobs with full thread pools on two cores
slow each other several times over.

Answer: see ``benchmarks/METHODS.md``, "Speed: the pair map and the merge without scipy's
per-call costs" (4 frames: 104 s with one worker, 75 s with two, at 25fa105).
"""

from __future__ import annotations

import sys
import time


def main() -> None:
    import fourd.bench.suite as suite
    from fourd import synth
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.hierarchy import assemble
    from fourd.methods.assembly.method import base_blocks, frame_meshes

    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    workers = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    truth = synth.scene("crane", frames=frames, seed=0, start=0, step=2)
    scans = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL)
    options = Options(workers=workers)
    blocks = base_blocks(scans, frame_meshes(scans, options))
    started = time.perf_counter()
    merged, reports = assemble(blocks, options)
    seconds = time.perf_counter() - started
    print(f"{frames} frames of {blocks[0].vertices.shape[1]} vertices, {len(reports)} merges, workers "
          f"{options.merge_workers(blocks[0].vertices.shape[1])}: {seconds:.1f} s, {seconds / frames:.1f} s per frame; "
          f"pasted {sum(r.pasted for r in reports)} vertices")


if __name__ == "__main__":
    main()
