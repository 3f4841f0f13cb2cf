"""Question: where do the handles of ``assembly``'s meshes come from, and where are they?

The closed result of all 17 dfaust-hopping frames has Euler characteristic -2 (genus 2), which a
hopping person does not have; crane's first 4 frames (every second) assemble to genus 22. Is the
genus in the per-frame surfaces the hierarchy starts from, or made by the merges, and where on
the body is it?

Run: ``.venv/bin/python experiments/assembly_handles.py [dfaust|crane|both] [OPEN_HANDLES]``
(crane: about a minute; ``OPEN_HANDLES`` the option's value for the crane assembly, 0 unless
given).

Measures:
- the first frame's own mesh (``_frame_meshes``): Euler characteristic, boundary loops (as the
  walk splits them at bow-ties) and the genus it would have with every loop capped by a disk;
- crane: the genus of each of 6 frames' own meshes, then the 4-frame assembly's genus and where
  its handles are. A vertex is flagged when the geodesic ball of 3 median edges around it is not
  a disk (Euler characteristic of its faces at most 0); the flags are clustered in space.

Answer (2026-12-04, 7247184, standard scans):
- dfaust-hopping, frame 0's own mesh: one piece, Euler -121, 115 boundary loops: genus 4 capped.
- crane frames 0-6 (every second), each frame's own mesh capped: genus 22, 5, 2, 0.5 (half values
  come from bow-tie loops). The count follows the scan's noise draw, not the pose: the same
  frame 0 scanned as the first of 1, 2 or 6 frames gives 0, 10 and 3. Across 6 frames,
  `agreement` 0.5, `normals_k` 24, `grid_scale` 0.8 and `bandwidth` 1.5 or 2.5 leave 0-7 a
  frame, as the defaults do (one-off runs of `frame_surface` with those settings).
- crane, 4 frames assembled: genus 22, the first frame's own genus. With the 6-frame scan's first
  4 frames the first frame has 3 and so does the assembly. Every frame is closed and manifold.
  Of 140 vertices flagged (every fourth vertex tested), 131 lie in one cluster at (1.14, 0.28,
  -0.21). There the truth has two sheets of skin facing each other (the legs, normals +0.74 and
  -0.89 in z) within 0.06, a few point spacings. The per-frame surface perforates that gap into a
  web of small tunnels.
So the whole animation takes the first frame's handles, since its connectivity is that frame's
mesh. The figures above are with ``open_handles=0``. The default now cuts the small handles out
and closes them with the holes (``geometry/hole_closing.py``, ``geometry/handles.py``):
crane's 4 frames go from genus 22 to 3, dfaust-hopping's 17 from 2 to 0. The fix at the source
would be the per-frame surface across a gap of a few spacings.
"""

import sys

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from fourd import synth
from fourd.bench.runner import PROTOCOL
from fourd.geometry.boundary_loops import boundary_loops
from fourd.geometry.geodesic import edge_length_graph, geodesic_ball, geodesic_scratch
from fourd.geometry.meshes import median_edge_length
from fourd.methods import reconstruct
from fourd.methods.assembly.method import _frame_meshes
from fourd.methods.assembly.options import Options
from fourd.metrics.topology import topology


def capped_genus(vertices, faces) -> float:
    found = topology(faces, len(vertices))
    loops = boundary_loops(faces, len(vertices))
    return (2 * found.components - found.euler - len(loops)) / 2


def not_a_disk(vertices, faces, radius_edges=3.0, stride=4) -> np.ndarray:
    """The tested vertices (every ``stride``-th) whose geodesic ball is not a disk."""
    graph, edge = edge_length_graph(vertices, faces), median_edge_length(vertices, faces)
    scratch, count = geodesic_scratch(len(vertices)), len(vertices)
    inside = np.zeros(count, dtype=bool)
    flagged = []
    for seed in range(0, count, stride):
        ball = geodesic_ball(graph, [seed], limit=radius_edges * edge, scratch=scratch)
        inside[ball.vertices] = True
        kept = faces[inside[faces].all(axis=1)]
        sides = np.sort(np.concatenate([kept[:, [0, 1]], kept[:, [1, 2]], kept[:, [2, 0]]]), axis=1)
        euler = len(np.unique(kept)) - len(np.unique(sides[:, 0] * count + sides[:, 1])) + len(kept)
        inside[ball.vertices] = False
        if euler <= 0:
            flagged.append(seed)
    return np.asarray(flagged, dtype=np.int64)


def dfaust() -> None:
    truth = synth.scene("dfaust-hopping", frames=2, seed=0)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    meshes, _ = _frame_meshes(scans, Options(), frames=slice(0, 1))
    vertices, faces = meshes[0]
    print("dfaust-hopping frame 0:", topology(faces, len(vertices)))
    print(f"  {len(boundary_loops(faces, len(vertices)))} boundary loops, capped genus "
          f"{capped_genus(vertices, faces):g}")


def crane() -> None:
    truth = synth.scene("crane", frames=4, seed=0, start=0, step=2)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    meshes, _ = _frame_meshes(scans, Options())
    print("crane, each frame's own mesh, capped genus:", [capped_genus(v, f) for v, f in meshes])
    result = reconstruct(scans, method="assembly", open_handles=int(sys.argv[2]) if len(sys.argv) > 2 else 0)
    vertices, faces = result.vertices[0], result.faces
    found = topology(faces, len(vertices))
    print(f"crane, 4 frames assembled: {found}, genus {(2 * found.components - found.euler) // 2}")
    flagged = not_a_disk(vertices, faces)
    pairs = cKDTree(vertices[flagged]).query_pairs(6 * median_edge_length(vertices, faces), output_type="ndarray")
    links = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(flagged),) * 2)
    clusters, label = connected_components(links, directed=False)
    print(f"  {len(flagged)} vertices flagged, {clusters} clusters; the largest:")
    for cluster in np.argsort(-np.bincount(label))[:5]:
        members = flagged[label == cluster]
        print(f"    {len(members)} at {np.round(vertices[members].mean(axis=0), 3).tolist()}")


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "both"
    if which in ("dfaust", "both"):
        dfaust()
    if which in ("crane", "both"):
        crane()
