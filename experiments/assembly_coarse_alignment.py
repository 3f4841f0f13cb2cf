"""Question: can the ARAP-ICP behind `assembly`'s geometric anchors run its stiff iterations on
a decimated source (a quarter of the faces) and keep its accuracy, for a merge about a third
of which was that alignment?

Setup: one pair of the bench's crane frames (standard scan, meshed as ``assembly`` meshes
them), rigidly aligned, then registered two ways: ``nonrigid_icp`` at full resolution, and
the source decimated by ``REDUCTION`` of its faces (quadric decimation), ``COARSE_ITERATIONS``
times the stiff iterations with the data weight scaled by ``WEIGHT_SCALE`` (1: as at full
resolution; the method uses the squared edge ratio), carried back by inverse-distance weights
of the non-rigid displacement, then the three soft iterations at full resolution. Printed:
both times, how far apart the two results lie and how far each lies from the target (source
edges).

Run: ``.venv/bin/python experiments/assembly_coarse_alignment.py A B [REDUCTION [WEIGHT_SCALE
[COARSE_ITERATIONS]]]`` (A, B: bench frame indices, 0-19)

Answer (2-core machine, 2026-12-01, at 2675ff8, weight 1, iterations 1): frames 0-1 full
3.18 s, coarse 1.64 s, the results 0.021 / 0.120 / 0.60 edges apart (median / 95th
percentile / largest), median gap to the target 0.244 vs 0.252 edges; 0-3 0.019 / 0.059 /
0.36; 0-6 0.035 / 0.189 / 1.00; 10-13 0.286 / 2.94 / 4.35 (gaps 0.38 vs 0.40). The bench
decided (``benchmarks/METHODS.md``, "Speed: the coarse alignment"): the weight as at full
resolution left crane's limbs behind (0.0075 / 0.0101), the squared edge ratio gave 0.0061 /
0.0087, twice the iterations 0.0060 / 0.0084 (0.0062 / 0.0090 at full resolution). On
bending-arm's swing (``tests/methods/assembly/test_geometric_alignment.py``) the coarse
mesh creeps towards the forearm by smaller steps: 50 iterations at half the faces left it 13
edges behind, 100 within 5, 200 within 3.9 (3.6 at full resolution).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.spatial import cKDTree

from fourd import synth
from fourd.geometry.decimation import decimate
from fourd.geometry.meshes import median_edge_length
from fourd.geometry.normals import vertex_normals
from fourd.geometry.rotations import procrustes
from fourd.methods.assembly import alignment
from fourd.methods.assembly.method import frame_meshes
from fourd.methods.assembly.options import Options


def main() -> None:
    a, b = int(sys.argv[1]), int(sys.argv[2])
    reduction = float(sys.argv[3]) if len(sys.argv) > 3 else 0.75
    weight_scale = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
    iterations = int(sys.argv[5]) if len(sys.argv) > 5 else 1
    truth = synth.scene("crane", frames=20, start=0, step=2)
    scans = synth.scan(truth, resolution=256, seed=0)
    meshes = frame_meshes(scans[min(a, b):max(a, b) + 1], Options())
    (source, faces), (target, target_faces) = meshes[a - min(a, b)], meshes[b - min(a, b)]
    source, faces = np.asarray(source, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    target_normals = vertex_normals(target, target_faces)
    tree = cKDTree(target)
    rigid = alignment.rigid_icp(source, vertex_normals(source, faces), target, target_normals, iterations=10,
                                tree=tree)
    started = time.perf_counter()
    full = alignment.nonrigid_icp(source, faces, target, target_normals, rigid, tree=tree)
    full_seconds = time.perf_counter() - started
    edge = median_edge_length(source, faces)
    started = time.perf_counter()
    coarse = decimate(source, faces, reduction)
    fit = procrustes(source, rigid)
    start = coarse.vertices @ fit.rotation.T + fit.translation
    ratio = edge / median_edge_length(coarse.vertices, coarse.faces)
    moved = alignment.nonrigid_icp(coarse.vertices, coarse.faces, target, target_normals, start,
                                   iterations=50 * iterations, weight=0.001 * weight_scale,
                                   start_radius=alignment.START_RADIUS * ratio,
                                   end_radius=alignment.END_RADIUS * ratio, refine_iterations=0, tree=tree)
    followed = rigid + coarse.carry(moved - start + coarse.vertices)
    fine = alignment.nonrigid_icp(source, faces, target, target_normals, followed, iterations=0, tree=tree)
    coarse_seconds = time.perf_counter() - started
    apart = np.linalg.norm(fine - full, axis=1) / edge
    print(f"{a}->{b}: {len(coarse.vertices)} coarse vertices (edges {1 / ratio:.2f} times); full {full_seconds:.2f} s, "
          f"coarse {coarse_seconds:.2f} s; apart median {np.median(apart):.3f} 95th {np.percentile(apart, 95):.3f} "
          f"largest {apart.max():.2f} edges")
    for name, x in (("full", full), ("coarse", fine)):
        gap, _ = tree.query(x)
        print(f"{name}: gap to the target median {np.median(gap) / edge:.3f}, 95th {np.percentile(gap, 95) / edge:.3f} edges")


if __name__ == "__main__":
    main()
