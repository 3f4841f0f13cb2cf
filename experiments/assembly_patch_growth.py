"""Question: how long does the patch growth of one `assembly` merge take, how many pairs does
it keep and how much of the source do they cover? (Run it at two commits to compare them, as
for the growth changes in ``benchmarks/METHODS.md``, "Speed: closest points, the rigid fit on
a subset, ...".)

Setup: the first pair of crane (frames 0 and 2, step 2) and of dfaust-hopping (frames 0 and
1), each frame meshed by the assembly's own meshing (standard scan, seed 0); the geometric
anchors and the pair map's options at their defaults; the growth timed on its second run (the
first compiles).

Run: ``PYTHONPATH=src .venv/bin/python experiments/assembly_patch_growth.py``

Answer (2-core AMD EPYC, nothing else running, 2026-12-01), growth s / pairs kept / pairs
given up / source covered:

| commit | crane | dfaust-hopping |
|---|---|---|
| 77211dd (the growth of e65200b) | 1.59 / 1,291 / 592 / 97.97% | 5.95 / 2,435 / 2,478 / 97.25% |
| f91c38e (image search by anchor) | 1.44, the same pairs | 5.02, the same pairs |
| a442414 (retry at `min_anchors`) | 1.46 / 1,306 / 461 / 98.40% | 4.98 / 2,588 / 1,537 / 98.37% |
| 6921328 (uncovered anchors first) | 1.13 / 1,195 / 401 / 98.25% | 3.68 / 2,302 / 1,302 / 98.21% |
| 1fe749e (a ball's vertices compiled) | 1.00, the same pairs | 3.64, the same pairs |
"""

from __future__ import annotations

import time

from fourd import synth
from fourd.methods.assembly.alignment import geometric_anchors
from fourd.methods.assembly.method import frame_meshes
from fourd.methods.assembly.options import Options
from fourd.methods.assembly.patches import grow_patches


def main() -> None:
    options = Options()
    for scene, step in (("crane", 2), ("dfaust-hopping", 1)):
        scans = synth.scan(synth.scene(scene, frames=2, start=0, step=step), seed=0)
        (v0, f0), (v1, f1) = frame_meshes(scans, options)
        anchors = geometric_anchors(v0, f0, v1, f1, spacing=options.anchor_spacing,
                                    settle=options.alignment_settle).anchors
        crossparam = options.pair_options().crossparam
        grow_patches(v0, f0, v1, f1, anchors, crossparam)
        started = time.perf_counter()
        grown = grow_patches(v0, f0, v1, f1, anchors, crossparam)
        seconds = time.perf_counter() - started
        print(f"{scene}: {len(v0)} vertices, {len(anchors.source)} anchors; growth {seconds:.2f} s, "
              f"{len(grown.pairs)} pairs kept, {grown.discarded} given up, {100 * grown.covered.mean():.2f}% covered")


if __name__ == "__main__":
    main()
