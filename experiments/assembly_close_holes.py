"""Question: what does closing the holes no frame fills (`assembly`'s ``close_holes``, the C1
membrane of thesis 3.6.2 placed in every frame from that frame's rim) do to completeness and
accuracy?

Setup: ``SCENE`` (crane by default, the bench's 20-frame stretch, every 2nd capture frame; any
bench scene name) at the bench's standard scan, ``FRAMES`` frames (4 by default); the assembly
run once (``close_holes`` 0; kept in the temporary folder, so a rerun only scores), then the same result scored as it is and with its holes closed at
``FRACTION`` (0.25 by default) with the C1 membrane, a third of its C1 weight and the flat
one (``close_smoothness`` 1, 0.3, 0), by ``fourd.metrics.evaluate`` at the bench's 60,000 samples.

Run: ``.venv/bin/python experiments/assembly_close_holes.py [SCENE [FRAMES [FRACTION]]]``

Answer (2-core machine, 4 frames; Chamfer / completeness-95 / correspondence mean): crane as
assembled 0.0023 / 0.0115 / 0.0019; C1 0.0029 / 0.0072 / 0.0028; flat 0.0023 / 0.0048 / 0.0022.
touching-spheres 0.0047 / 0.0488 / 0.0457; C1 0.0026 / 0.0076 / 0.0460; flat 0.0061 / 0.0373 /
0.0470. dfaust-hopping 0.0026 / 0.0153 / 0.0030; C1 0.0029 / 0.0096 / 0.0035; flat 0.0027 /
0.0104 / 0.0032. See ``benchmarks/METHODS.md``, "Holes no frame fills (`close_holes`, off)".
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np


def main() -> None:
    import fourd.bench.suite as suite
    from fourd import synth
    from fourd.animation import AnimatedMesh
    from fourd.geometry.hole_closing import close_small_holes
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.hierarchy import Block, assemble
    from fourd.methods.assembly.method import base_blocks, frame_meshes
    from fourd.metrics import evaluate

    name = sys.argv[1] if len(sys.argv) > 1 else "crane"
    frames = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    fraction = float(sys.argv[3]) if len(sys.argv) > 3 else 0.25
    bench = next(s for s in suite.STANDARD_SCENES if s.name == name)
    truth = synth.scene(name, frames=frames, seed=0, **bench.options)
    scans = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL)
    options = Options(close_holes=0.0)
    kept = Path(tempfile.gettempdir()) / f"assembly_close_holes_{name}_{frames}.npz"  # reruns score it anew
    if kept.exists():
        block = Block(**np.load(kept))
    else:
        block, _ = assemble(base_blocks(scans, frame_meshes(scans, options)), options)
        np.savez(kept, **block._asdict())
    variants = [("as assembled", block)] + [(f"closed at {fraction}, smoothness {smoothness}",
                                             Block(*close_small_holes(*block, fraction, smoothness)))
                                            for smoothness in (1.0, 0.3, 0.0)]
    for label, result in variants:
        mesh = AnimatedMesh(result.faces, result.vertices, scans.times, result.observed, rest=result.vertices[0])
        m = evaluate(mesh, truth, samples=60000, seed=0)
        print(f"{name}, {frames} frames, {label}: {result.vertices.shape[1]} vertices, accuracy {m['accuracy']:.4f}, "
              f"completeness {m['completeness']:.4f}, Chamfer {m['chamfer']:.4f}, completeness-95 "
              f"{m['completeness_95']:.4f}, correspondence {m['correspondence_mean']:.4f} / "
              f"{m['correspondence_last']:.4f}, closed {m['closed_manifold']}, observed "
              f"{np.mean(result.observed):.3f}")


if __name__ == "__main__":
    main()
