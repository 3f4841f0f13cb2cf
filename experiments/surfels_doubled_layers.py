"""Question: since the part search (twelfth session) `surfels`' crane and crane-90 meshes are no
longer closed: a closed body and 1-2 small pieces beside it. What are the small pieces, and
does the closing's doubled-layer rule (`fourd.geometry.doubled_layers`: a piece with at most a
hundredth of the largest piece's faces, whose vertices lie at a median distance of at most two
median edges from the larger surface) take exactly them?

    PYTHONPATH=src:experiments python experiments/surfels_doubled_layers.py crane-90 [crane ...]

Runs `surfels` with its defaults on the bench scene's scans, once with the closing off
(`close_holes` 0; the merges cached in /tmp/surfels-doubled/cache-LABEL, so the second run
only meshes again), and for each piece of frame 0's mesh but the largest: its faces, whether it
is open, its median and largest distance to the largest piece in median edge lengths, before
the closing and after it (to the closed body, membranes included). Then the default run's
pieces and watertight frames.

Answer (2026-12-06, thirteenth session, at 406a134; frame 0; faces, then distance to the body in
median edges, median / largest):

    crane-90  body 6,323 faces. Before the membranes: a sliver of 52 faces, open, 3.19 / 4.94
              from the open body; a closed bubble of 8 faces 0.77 / 0.81; five open crumbs of
              1-4 faces 0.78-2.03. After them the sliver lies 0.72 / 2.62 from the closed body:
              over the hole it left, now a membrane. Every small piece is dropped: one piece,
              a closed manifold (before the rule: 3 pieces, open).
    crane     body 10,419 faces; a sliver of 14 faces, open, 0.80 / 1.86; crumbs of 4 and 2
              faces 0.85 and 1.23. All dropped: one piece, a closed manifold (before: 2, open).

The sliver is observed surface on the truth, cut off by the meshing's clipping, and the body
beside it (a membrane on crane-90, a second layer where the scan sees two on crane) lies within
a cell of it: nothing the body lacks is lost. The crane-50 pieces that are cut-off limb ends
(49, 37, 201 faces, `experiments/surfels_pieces.py`) lie farther than two edges from any other
surface and stay.
"""

from __future__ import annotations

import sys

import numpy as np
from surfels_alignment import scans_of

from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.geometry.hole_filling import fill_holes, small_holes
from fourd.geometry.meshes import face_pieces, median_edge_length
from fourd.methods import reconstruct
from fourd.metrics.topology import topology


def pieces_beside_the_body(vertices: np.ndarray, faces: np.ndarray) -> list[tuple]:
    """``(faces, open, median, largest)`` of each piece but the largest: distances from its
    vertices to the largest piece, in median edge lengths."""
    count, piece = face_pieces(faces)
    size = np.bincount(piece, minlength=count)
    body = np.argmax(size)
    unit = median_edge_length(vertices, faces)
    rows = []
    for label in np.argsort(-size):
        if label == body:
            continue
        own = faces[piece == label]
        distance = closest_points_on_mesh(vertices, faces[piece == body], vertices[np.unique(own)]).distances / unit
        shown = topology(own, len(vertices))
        rows.append((int(size[label]), not shown.closed_manifold, float(np.median(distance)), float(distance.max())))
    return rows


def main(labels: list[str]) -> None:
    for label in labels:
        _, scans = scans_of(label)
        cache = f"/tmp/surfels-doubled/cache-{label}"
        open_mesh = reconstruct(scans, method="surfels", cache_dir=cache, close_holes=0.0)
        vertices, faces = open_mesh.vertices[0], open_mesh.faces
        print(f"{label}: body of {np.bincount(face_pieces(faces)[1]).max()} faces")
        for row in pieces_beside_the_body(vertices, faces):
            print("  before closing: {} faces, open {}, {:.2f} edges from the body (median), at most {:.2f}".format(*row))
        # the membranes alone (the closing's first steps), to measure against the closed body
        holes = small_holes(vertices, faces, max_fraction=0.25)
        closed = fill_holes(vertices, faces, holes=holes, area_matched=True, smooth=1.0)
        for row in pieces_beside_the_body(closed.vertices, closed.faces):
            print("  after the membranes: {} faces, open {}, {:.2f} edges from the body, at most {:.2f}".format(*row))
        default = reconstruct(scans, method="surfels", cache_dir=cache)
        shown = topology(default.faces, default.vertices.shape[1])
        print(f"  default: {shown.components} pieces, closed manifold {shown.closed_manifold}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["crane-90"])
