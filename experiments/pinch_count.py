"""Question: which methods' results have pinched vertices (two fans of faces meeting at a point
only, which Blender's "select non-manifold" and UV tools reject), and how many?

Setup: crane, ``FRAMES`` frames every 2nd capture frame from 0, the bench's standard scan; each
of ``METHODS`` (comma-separated) run with its defaults; the pinched vertices of its faces
counted (`geometry.fans.pinched_vertices`): once for an animated mesh, per frame (the first 8)
for per-frame meshes.

Run: ``.venv/bin/python experiments/pinch_count.py METHODS [FRAMES]``, e.g.
``experiments/pinch_count.py kinematic,surfels,perframe,flow,auto 8``.

Answer (2026-12-04, before the splits): kinematic 17, surfels 6, perframe 5-13 per frame, flow
and auto none; after them, none anywhere. ``benchmarks/METHODS.md``, "Pinched vertices in the
other methods' meshes".
"""

from __future__ import annotations

import sys
import time


def main() -> None:
    import fourd.bench.suite as suite
    from fourd import synth
    from fourd.geometry.fans import pinched_vertices
    from fourd.methods import reconstruct

    frames = int(sys.argv[2]) if len(sys.argv) > 2 else 8
    truth = synth.scene("crane", seed=0, frames=frames, start=0, step=2)
    seq = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL)
    for name in sys.argv[1].split(","):
        started = time.perf_counter()
        result = reconstruct(seq, method=name)
        seconds = time.perf_counter() - started
        if hasattr(result, "faces"):
            print(f"{name}: {result.vertex_count} vertices, {len(pinched_vertices(result.faces))} pinched ({seconds:.1f} s)")
        else:
            counts = [len(pinched_vertices(faces)) for _, faces in result.meshes[:8]]
            print(f"{name}: pinched per frame {counts} ({seconds:.1f} s)")


if __name__ == "__main__":
    main()
