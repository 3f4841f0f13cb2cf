"""Question: where does the hierarchy's time go on a whole stretch: do the cores idle while the
last merges run, and what do the joins cost?

Setup: ``SCENE`` (crane by default, ``FRAMES`` frames every 2nd capture frame from ``START``; a
procedural scene at its default 20 frames) at the bench's standard scan, each frame meshed as
the method does (not timed), then ``hierarchy.assemble`` with the default options (two worker
processes on a 2-core machine). Prints when each join ran (they run in this process: a join
follows its map's end and its right block's join) and the merges' total.

Run: ``.venv/bin/python experiments/assembly_schedule.py [FRAMES [SCENE [START]]]`` (20 crane
0). Nothing else should run beside it.

Answer (2-core AMD EPYC, 2026-12-01; ``benchmarks/METHODS.md``, "Speed: the hierarchy's
schedule and the join"): crane 0-38, merges 58.8 s at cd7fd58, the last two alone for 10.4 s;
54.8 s once the maps run by the longest chain after them (ef80e65), the last map beside frames
16-19's merges; 50.0 s with the registration's rotations only where used (458a800; crane from
130: 50.0 s). touching-spheres: 89.5 s, its last map (about 16 s) beside its right block's
merges, both ending together: its time is the maps' own work.
"""

from __future__ import annotations

import sys
import time


def main() -> None:
    import fourd.bench.suite as suite
    import fourd.methods.assembly.hierarchy as hierarchy
    from fourd import synth
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.method import base_blocks, frame_meshes

    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    scene = sys.argv[2] if len(sys.argv) > 2 else "crane"
    start = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    truth = (synth.scene(scene, frames=frames, seed=0, start=start, step=2) if scene == "crane"
             else synth.scene(scene))
    scans = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL)
    options = Options()
    blocks = base_blocks(scans, frame_meshes(scans, options))
    began = time.perf_counter()
    join = hierarchy.join_blocks

    def timed_join(left, right, pair, options):
        started = time.perf_counter()
        result = join(left, right, pair, options)
        print(f"join {len(left.vertices)} + {len(right.vertices)} frames: {started - began:.1f}-"
              f"{time.perf_counter() - began:.1f} s", flush=True)
        return result

    hierarchy.join_blocks = timed_join  # the joins run in this process
    hierarchy.assemble(blocks, options)
    print(f"{scene}, {len(blocks)} frames of {blocks[0].vertices.shape[1]} vertices: merges "
          f"{time.perf_counter() - began:.1f} s")


if __name__ == "__main__":
    main()
