"""Does pasting target-only geometry into the union mesh (thesis 5.6, second half; `assembly`'s
``paste``) complete what frame 0's scan misses, and at what cost?

Bench mode runs the bench on crane frames at the standard scan, ``frames`` of them every
``step``-th capture frame (4 and 2: the scene labelled ``crane-4`` in ``benchmarks/METHODS.md``),
with ``paste`` on and off, in one process (``isolate=False``), and prints the report's tables.
Pair mode merges two crane frames of the bench's 20-frame stretch (its frames 0 and 18, capture
frames 0 and 36) and prints the merge's report and the union's manifoldness.

    .venv/bin/python experiments/assembly_paste.py bench [frames [step]]
    .venv/bin/python experiments/assembly_paste.py pair

Answer: see ``benchmarks/METHODS.md``, "Pasting target-only geometry".
"""

from __future__ import annotations

import sys

import numpy as np

import fourd.bench.suite as suite
from fourd.bench.runner import run_bench


def bench(frames: int = 4, step: int = 2) -> None:
    label = f"crane-{frames}" if step == 2 else f"crane-{frames}-step-{step}"
    scene = suite.BenchScene("crane", frames=frames, options={"start": 0, "step": step}, label=label)
    suite.REMESHED_SCENES = suite.REMESHED_SCENES + (scene,)
    report = run_bench(
        methods=["assembly", "assembly:paste=false"],
        scenes=[label],
        isolate=False,
        output=f"benchmarks/out/assembly_paste_{label}.md",
    )
    for path in report["paths"]:
        if str(path).endswith(".md"):
            print(open(path).read())


def pair() -> None:
    import trimesh

    from fourd import synth
    from fourd.geometry.boundary_loops import boundary_loops
    from fourd.methods.assembly import Options, merge_blocks
    from fourd.methods.assembly.method import base_blocks, frame_meshes

    truth = synth.scene("crane", frames=20, seed=0, start=0, step=2)
    scans = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL).select(0, 20, 18)
    options = Options()
    left, right = base_blocks(scans, frame_meshes(scans, options))
    merged, report = merge_blocks(left, right, options)
    print(report)
    mesh = trimesh.Trimesh(merged.vertices[1], merged.faces, process=False)
    _, uses = np.unique(np.sort(mesh.edges, axis=1), axis=0, return_counts=True)
    loops = boundary_loops(merged.faces, len(mesh.vertices))
    print(f"frame 0: {left.vertices.shape[1]} vertices; union: {len(mesh.vertices)}; consistently "
          f"oriented {mesh.is_winding_consistent}; most faces on an edge {uses.max()}; "
          f"longest rims {[len(loop) for loop in loops[:5]]}")


if __name__ == "__main__":
    mode, *args = sys.argv[1:] or ["bench"]
    (bench if mode == "bench" else pair)(*(int(a) for a in args))
