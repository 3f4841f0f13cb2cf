"""Question: does ``assembly``'s assembled mesh have pinched vertices (two fans of faces meeting
at a point only), which the sides-only "closed & manifold" count passed, and does the closing
step leave the result without them?

Run: ``.venv/bin/python experiments/assembly_pinches.py [START ...]`` (crane stretches of 20
frames, every second frame, starting at START; 0 and 130 unless given; about two minutes each).

Measures, on the assembled mesh as the closing step receives it (its first frame): the pinched
vertices (``geometry.fans.pinched_vertices``), boundary loops and the capped genus; then the
result's topology (``metrics.topology``, which now counts pinches).

Answer (2026-12-04, standard scans, default options):
- crane-0: the assembled mesh has 4 pinched vertices, 14 boundary loops, capped genus 0;
  crane-130: 7, 27 and 6. The counter before pinches were counted passed both results as closed
  and manifold, yet each was 3 pieces: the body and two "pillows" of 2 faces. A single triangle
  hanging from the surface by one vertex (the per-frame surface fraying) has a loop of 3 sides,
  which the hole filling capped with the reverse triangle.
- With such flaps dropped first (pieces at most a hundredth of the piece they touch,
  ``geometry.fans.fragments``: 2 faces on crane-0, 3 on crane-130) and any pinch left split:
  both results are one piece, closed, manifold, no pinch, Euler characteristic 2.
"""

import sys

from fourd import synth
from fourd.bench.runner import PROTOCOL
from fourd.geometry import hole_closing as closing
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.fans import pinched_vertices
from fourd.geometry.handles import capped_genus
from fourd.methods import reconstruct
from fourd.metrics.topology import topology


def run(start: int) -> None:
    truth = synth.scene("crane", frames=20, seed=0, start=start, step=2)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    seen = []
    holes_to_close = closing.holes_to_close

    def recording(first, faces, *args, **kwargs):
        seen.append(faces)
        return holes_to_close(first, faces, *args, **kwargs)

    closing.holes_to_close = recording
    try:
        result = reconstruct(scans, method="assembly")
    finally:
        closing.holes_to_close = holes_to_close
    faces = seen[0]
    count = int(faces.max()) + 1
    print(f"crane-{start}, assembled: {len(pinched_vertices(faces))} pinched vertices, "
          f"{len(boundary_loops(faces, count))} boundary loops, capped genus {capped_genus(faces, count)}")
    print(f"  result: {topology(result.faces, result.vertex_count)}")


if __name__ == "__main__":
    for start in [int(s) for s in sys.argv[1:]] or [0, 130]:
        run(start)
