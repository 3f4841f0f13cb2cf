"""Question: the 20-frame crane bench of `assembly` drifts little over frames 0-7 (0.001-0.006)
and then climbs to 0.054 by frame 12. Is that one bad pair map, several, or the hierarchy
compounding small ones? What distinguishes the bad pairs (motion, anchors, mapped fraction)?

Setup: the bench's crane (20 frames, every 2nd capture frame, standard scan, each frame meshed
as the method does). For each consecutive pair (t, t+1) given in ``PAIRS`` (all by default),
one merge of the two single-frame blocks (`hierarchy.merge_blocks`, default options, or with
``correct`` and ``paste`` when ``CORRECT=1``); the
source's vertices bound to the truth's frame t and followed along the true motion to t+1;
error of the merged block's frame t+1 against that, fractions of the diagonal, over the mapped
vertices and over all. Also: the truth's motion between the two frames (mean and 95th
percentile of the truth vertices' displacement), the anchors and the mapped fraction.

Run: ``.venv/bin/python experiments/assembly_pair_errors.py [SCENE] [PAIRS...]`` (nothing else
running; SCENE a bench scene as ``fourd bench`` scans it, ``crane`` by default).

Answer (at 39efc63, nothing else running): single pair maps, over the kick. Pair 0 -> 1: a
step of 0.0016, mapped vertices 0.0017 off; 8 -> 9, 9 -> 10, 10 -> 11: steps of 0.022-0.028,
mapped vertices 0.0145, 0.0183, 0.0142 off. The anchors' coarse alignment hardly moved the
leg; with ARAP-ICP (f6b8f5f) 0.0039, 0.0051, 0.0045. Tables in ``benchmarks/METHODS.md``,
"Where the 20-frame crane drifts".

dfaust-hopping (at 96cfe67): every pair loses most of its tangential step (pair 8 -> 9: step
0.0038, error 0.0030 of which 0.0028 tangential); the coarse alignment pinned sliding surfaces.
Now the truth's displacement is added to the vertex (a point truth binds to its nearest point,
up to half its spacing away). Fixed by the point-to-plane ARAP-ICP; ``benchmarks/METHODS.md``,
"Where dfaust-hopping drifts".

With the analysis and correction (``CORRECT=1``: ``correct`` and ``paste``; 2026-11-30, after
the islands' rule of `analysis._fill_islands`), pairs 0, 8, 9, 10: 4,279-9,950 of the 34,000
vertices flagged in 159-194 regions, 1-13 deleted; mapped error 0.0011 / 0.0033 / 0.0039 /
0.0043 against 0.0011 / 0.0033 / 0.0038 / 0.0034 without, all vertices' 95th percentile at
10 -> 11 0.0168 against 0.0070. The stretch flags of scanned frames are their meshes' noise,
not a topology change: `correct` stays off.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np


def main() -> None:
    import fourd.bench.suite as suite
    from fourd.geometry.normals import vertex_normals
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.hierarchy import merge_blocks
    from fourd.methods.assembly.method import base_blocks, frame_meshes
    from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface

    arguments = sys.argv[1:]
    name = arguments.pop(0) if arguments and not arguments[0].isdigit() else "crane"
    bench = suite.select_scenes([name], quick=False)[0]
    truth, scans = suite.scan_scene(bench)
    pairs = [int(a) for a in arguments] or list(range(len(scans) - 1))
    options = Options(workers=1, correct=os.environ.get("CORRECT") == "1", paste=os.environ.get("CORRECT") == "1")
    blocks = base_blocks(scans, frame_meshes(scans, options))
    diagonal = truth.diagonal()
    rng = np.random.default_rng(0)
    print(f"correct={options.correct}")
    print("pair  motion_mean motion_95  anchors mapped  err_mapped err_all err_95  normal tangential  seconds")
    for t in pairs:
        started = time.perf_counter()
        merged, report = merge_blocks(blocks[t], blocks[t + 1], options)
        seconds = time.perf_counter() - started
        samples = sample_surface(truth.vertices[t], truth.faces, 20000, rng)
        binding = bind_to_surface(merged.vertices[0], truth.vertices[t], truth.faces, samples)
        followed = bound_positions(binding, truth.vertices[t:t + 2], truth.faces)
        # the truth's displacement added to the vertex (a point truth binds to its nearest
        # point, up to half its spacing away: comparing positions would count that offset)
        difference = (merged.vertices[1] - merged.vertices[0] - (followed[1] - followed[0])) / diagonal
        error = np.linalg.norm(difference, axis=1)
        normal = np.abs(np.einsum("nd,nd->n", difference, vertex_normals(merged.vertices[1], merged.faces)))
        tangential = np.sqrt(np.maximum(error**2 - normal**2, 0.0))
        seen = merged.observed[1]
        motion = np.linalg.norm(truth.vertices[t + 1] - truth.vertices[t], axis=1) / diagonal
        print(f"{t:2d}->{t + 1:<2d} {motion.mean():.4f}      {np.percentile(motion, 95):.4f}     "
              f"{report.anchors:5d}  {report.mapped:.3f}   {error[seen].mean():.4f}     {error.mean():.4f}  "
              f"{np.percentile(error, 95):.4f}  {normal[seen].mean():.4f} {tangential[seen].mean():.4f}  "
              f"{seconds:6.1f}  flagged {report.flagged} regions {report.regions} deleted {report.deleted}", flush=True)


if __name__ == "__main__":
    main()
