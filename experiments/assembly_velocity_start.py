"""Question: on the perfect per-frame meshes of `crane-remeshed` the assembly's correspondence
climbs over the kick (frames 8-13) and every pair's error there is tangential (pair 9 -> 10
moves 0.026 of the diagonal on average and is 0.0034 off, all of it along the surface;
`experiments/assembly_pair_errors.py crane-remeshed`). Where does the slide come from: the
alignment (ARAP-ICP) or the patches' maps after it? Is it the fast leg? And does the left
block's own motion (its last step repeated: constant velocity) as the ARAP-ICP's start, where
the block has two frames, cut it?

Setup: a bench scene as ``fourd bench`` scans it, each frame meshed as the method does; for each
pair ``t -> t + 1`` asked (``t`` at least 1): the source is frame ``t``'s mesh, the goal of each
of its vertices its position plus the truth's step at its bound point. Errors in fractions of
the diagonal, means over the vertices: of the alignment as the method makes it
(:func:`~fourd.methods.assembly.alignment.geometric_anchors`, default options), of its
anchors, of the pair map (:func:`~fourd.methods.assembly.hierarchy.map_pair`, mapped vertices),
on the 10% fastest vertices, and by height quartile; the alignment's mean error vector and what
is left after the best rigid correction of it. Then the ARAP-ICP
(:func:`~fourd.methods.assembly.alignment.nonrigid_icp`, the method's settings) from the rigid
ICP of ``x_t + DAMPING (x_t - x_{t-1})`` instead of ``x_t``, ``x_{t-1}`` the previous frame's
mesh mapped onto frame ``t`` by the method's merge (the rest shape stays ``x_t``).

Run: ``.venv/bin/python experiments/assembly_velocity_start.py [SCENE] [PAIRS...]`` (SCENE a
bench scene, ``crane-remeshed`` by default; ``DAMPING`` 1 by default).

Answer (2026-12-04, 30a5271, crane-remeshed pairs 9 -> 10, 10 -> 11, 11 -> 12): the alignment.
Its error is the pair map's to within 0.0001 (0.0035 / 0.0029 / 0.0016 against the map's
0.0034 / 0.0028 / 0.0016): the patches carry the anchors' slide, they add none. It is not the
leg: the 10% fastest vertices are 0.0032 / 0.0036 / 0.0017 off, the whole body about as much,
most in the middle two height quartiles (hips and torso, 0.0046 and 0.0042 on pair 9 -> 10,
feet 0.0024); the mean error is 0.0017 upwards, and the best rigid correction leaves 0.0032 of
the 0.0035. A non-rigid slide of the torso along itself, which point-to-plane data and the
ARAP prior (rest shape: frame ``t``) do not determine (pair 11 -> 12: 0.0009 upwards, 0.0014
left after the rigid correction of 0.0016). The constant-velocity start changes next to nothing:
the ARAP-ICP alone 0.0035 -> 0.0034 on 9 -> 10, 0.0016 -> 0.0015 on 11 -> 12 (and in a first
version that passed the start through `map_pair`, the map 0.0034 -> 0.0033, 0.0016 -> 0.0016,
0.0021 -> 0.0021 on 9 -> 10, 11 -> 12, 13 -> 14): the search starts 40 edges wide and comes to the same
rest from either start. Not kept.
"""

from __future__ import annotations

import os
import sys

import numpy as np


def main() -> None:
    import fourd.bench.suite as suite
    from fourd.geometry.normals import vertex_normals
    from fourd.geometry.rotations import procrustes
    from fourd.methods.assembly import Options
    from fourd.methods.assembly.alignment import geometric_anchors, nonrigid_icp, rigid_icp
    from fourd.methods.assembly.hierarchy import map_pair, merge_blocks
    from fourd.methods.assembly.method import base_blocks, frame_meshes
    from fourd.metrics.sampling import bind_to_surface, bound_positions, sample_surface

    arguments = sys.argv[1:]
    name = arguments.pop(0) if arguments and not arguments[0].isdigit() else "crane-remeshed"
    damping = float(os.environ.get("DAMPING", "1"))
    bench = suite.select_scenes([name], quick=False)[0]
    truth, scans = suite.scan_scene(bench)
    pairs = [int(a) for a in arguments] or list(range(1, len(scans) - 1))
    options = Options(workers=1)
    meshes = frame_meshes(scans, options)
    blocks = base_blocks(scans, meshes)
    diagonal = truth.diagonal()
    rng = np.random.default_rng(0)
    for t in pairs:
        (source, faces), (target, target_faces) = meshes[t], meshes[t + 1]
        samples = sample_surface(truth.vertices[t], truth.faces, 20000, rng)
        binding = bind_to_surface(source, truth.vertices[t], truth.faces, samples)
        followed = bound_positions(binding, truth.vertices[t:t + 2], truth.faces)
        goal = source + (followed[1] - followed[0])
        motion = np.linalg.norm(followed[1] - followed[0], axis=1) / diagonal
        fast = motion > np.percentile(motion, 90)

        alignment = geometric_anchors(
            source, faces, target, target_faces, spacing=options.anchor_spacing, gap=options.anchor_gap,
            tolerance=options.anchor_tolerance, iterations=options.alignment_iterations,
            weight=options.alignment_weight, coarse=options.alignment_coarse, settle=options.alignment_settle,
            seed=options.seed,
        )
        aligned_error = np.linalg.norm(alignment.aligned - goal, axis=1) / diagonal
        anchors = alignment.anchors
        points = np.einsum("nk,nkd->nd", anchors.target_barycentric, target[target_faces[anchors.target_faces]])
        anchor_error = np.linalg.norm(points - goal[anchors.source], axis=1) / diagonal
        pair = map_pair(source, faces, target, target_faces, options)
        mapped = pair.mapped
        image = np.einsum("nk,nkd->nd", pair.barycentric[mapped], target[target_faces[pair.faces[mapped]]])
        map_error = np.linalg.norm(image - goal[mapped], axis=1) / diagonal
        print(f"{t}->{t + 1}: motion {motion.mean():.4f}; alignment {aligned_error.mean():.4f} "
              f"(fastest 10%: {aligned_error[fast].mean():.4f}); {len(anchors.source)} anchors "
              f"{anchor_error.mean():.4f}; map {map_error.mean():.4f} (fastest {map_error[fast[mapped]].mean():.4f})")
        offset = (alignment.aligned - goal).mean(axis=0) / diagonal
        fit = procrustes(alignment.aligned, goal)
        rigid = alignment.aligned @ fit.rotation.T + fit.translation
        print(f"  mean error {np.round(offset, 4)}; after the best rigid correction "
              f"{(np.linalg.norm(rigid - goal, axis=1) / diagonal).mean():.4f}")
        height = source[:, 1]
        edges = np.percentile(height, [0, 25, 50, 75, 100])
        quartiles = [
            f"{aligned_error[(height >= lo) & (height <= hi)].mean():.4f}"
            for lo, hi in zip(edges[:-1], edges[1:], strict=True)
        ]
        print(f"  by height quartile, lowest first: {' '.join(quartiles)}")

        # the ARAP-ICP from the left block's last step repeated
        left, _ = merge_blocks(blocks[t - 1], blocks[t], options)
        previous = left.vertices[0]  # frame t-1's mesh on frame t-1
        # frame t in frame t-1's connectivity is left.vertices[1]; its step, carried to frame
        # t's own vertices by their nearest vertex there
        from scipy.spatial import cKDTree

        _, nearest = cKDTree(left.vertices[1]).query(source)
        step = (left.vertices[1] - previous)[nearest]
        normals = vertex_normals(target, target_faces)
        starts = {"as now": rigid_icp(source, vertex_normals(source, faces), target, normals),
                  "velocity": rigid_icp(source + damping * step, vertex_normals(source + damping * step, faces),
                                        target, normals)}
        for label, start in starts.items():
            moved = nonrigid_icp(source, faces, target, normals, start, iterations=options.alignment_iterations,
                                 weight=options.alignment_weight, settle=options.alignment_settle)
            print(f"  ARAP-ICP from {label}: {(np.linalg.norm(moved - goal, axis=1) / diagonal).mean():.4f}",
                  flush=True)


if __name__ == "__main__":
    main()
