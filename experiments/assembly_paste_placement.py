"""Question: where is the geometry that ``paste`` glues in (thesis 5.6) off the true surface, in
the frames before the one that saw it, and does placing it frame by frame (each frame from the
one after it) instead of from the target frame at once bring it onto the surface?

Setup: ``SCENE`` (crane-90 by default: the held-out crane stretch from capture frame 90, every
2nd frame; any bench scene name) at the bench's standard scan, ``FRAMES`` frames (20 by
default), assembled with ``paste`` on and ``close_holes`` 0 (kept in the temporary folder under
``TAG``, so a rerun only scores). Then, per frame, the distance from each vertex to the true
surface (in bench diagonals), median and 95th percentile, over the pasted vertices (those after
the first frame's mesh) and over the others, and the bench's scores. Run it from two checkouts
(``PYTHONPATH=<checkout>/src``) with different tags to compare placements.

Run: ``.venv/bin/python experiments/assembly_paste_placement.py [SCENE [FRAMES [TAG]]]``

Answer (2-core machine, crane-90, 20 frames; per-frame median / 95th percentile distance of the
pasted vertices, then accuracy / Chamfer / completeness-95 / correspondence mean / last): placed
from the target frame at once (5856f25) frame 0 0.0152 / 0.0521, frames 1-11 up to 0.0150 /
0.1416, 0.0079 / 0.0050 / 0.0054 / 0.0141 / 0.0224; frame by frame 0.0186 / 0.0409, frames 1-11
up to 0.0177 / 0.0791, 0.0052 / 0.0036 / 0.0055 / 0.0140 / 0.0225. The others' vertices 0.0007 /
0.0025-0.0048 either way. Three patches were pasted, the largest 542 vertices across 0.21 of the
diagonal with 109 on the seam: never seen before frame 14, their shape there is a guess, off by
0.010-0.026 (median) whichever way it is made. See ``benchmarks/METHODS.md``, "`paste` placed
frame by frame".
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np


def main() -> None:
    import trimesh

    import fourd.bench.suite as suite
    from fourd import synth
    from fourd.animation import AnimatedMesh
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.hierarchy import Block, assemble
    from fourd.methods.assembly.method import base_blocks, frame_meshes
    from fourd.metrics import evaluate

    name = sys.argv[1] if len(sys.argv) > 1 else "crane-90"
    frames = int(sys.argv[2]) if len(sys.argv) > 2 else 20
    tag = sys.argv[3] if len(sys.argv) > 3 else "head"
    bench = next(s for s in suite.STANDARD_SCENES + suite.HELD_OUT_SCENES if s.key == name)
    truth = synth.scene(bench.name, frames=frames, seed=0, **bench.options)
    scans = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL)
    options = Options(close_holes=0.0, paste=True)
    kept = Path(tempfile.gettempdir()) / f"assembly_paste_placement_{name}_{frames}_{tag}.npz"
    if not kept.exists():
        blocks = base_blocks(scans, frame_meshes(scans, options))
        block, _ = assemble(blocks, options)
        np.savez(kept, **block._asdict(), first_count=blocks[0].vertices.shape[1])
    stored = dict(np.load(kept))
    count = int(stored.pop("first_count"))
    block = Block(**stored)
    diagonal = truth.diagonal()
    pasted = np.arange(block.vertices.shape[1]) >= count
    print(f"{name}, {frames} frames, {tag}: {block.vertices.shape[1]} vertices, {pasted.sum()} pasted")
    for t in range(frames):
        tv, tf = truth.frame(t)
        distance = np.abs(trimesh.proximity.signed_distance(trimesh.Trimesh(tv, tf, process=False),
                                                            block.vertices[t])) / diagonal
        own, rest = distance[pasted], distance[~pasted]
        print(f"  frame {t:2d}: pasted {np.median(own) if len(own) else 0:.4f} / "
              f"{np.percentile(own, 95) if len(own) else 0:.4f}, others {np.median(rest):.4f} / "
              f"{np.percentile(rest, 95):.4f}")
    mesh = AnimatedMesh(block.faces, block.vertices, scans.times, block.observed, rest=block.vertices[0])
    m = evaluate(mesh, truth, samples=60000, seed=0)
    print(f"  accuracy {m['accuracy']:.4f}, Chamfer {m['chamfer']:.4f}, completeness-95 "
          f"{m['completeness_95']:.4f}, correspondence {m['correspondence_mean']:.4f} / "
          f"{m['correspondence_last']:.4f}")


if __name__ == "__main__":
    main()
