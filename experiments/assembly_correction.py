"""Does the analysis and correction of `assembly` (thesis 5.5, ``correct``) cut a glued contact
that the next frame breaks?

Merges `touching-spheres` remeshed at 64 rays (no noise), frame 10 (glued) onto frame 11 (just
apart), with and without ``correct``, and prints each merge's report and the result's pieces.

    .venv/bin/python experiments/assembly_correction.py

Answer: no. 22 regions, 667 of 2,864 vertices flagged, but every region's Laplacian placement
keeps the source's shape and passes the stretch test, so the neck stays (one piece either way).
Two spheres 0.12 apart in the target (the test ``test_a_bridge_the_next_frame_breaks_is_found_and_cut``)
do come out as two pieces.
"""

from __future__ import annotations

import numpy as np

import fourd
from fourd.geometry.meshes import vertex_components
from fourd.methods.assembly import Block, Options, merge_blocks


def main() -> None:
    truth = fourd.synth.scene("touching-spheres", frames=20)
    scans = fourd.synth.scan(truth, resolution=64, seed=0, mode="remeshed")

    def block(i):
        frame = scans.frames[i]
        points = np.asarray(frame.points)
        return Block(np.asarray(frame.faces), points[None], np.ones((1, len(points)), dtype=bool))

    for correct in (False, True):
        merged, report = merge_blocks(block(10), block(11), Options(correct=correct))
        pieces, _ = vertex_components(merged.faces, merged.vertices.shape[1])
        print(f"correct={correct}: {report}; {pieces} pieces; {merged.vertices.shape[1]} vertices")


if __name__ == "__main__":
    main()
