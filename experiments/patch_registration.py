"""Would a reduced, patch-wise rigid deformation model register ``kinematic``'s large motions
better than its as-rigid-as-possible ICP? An experiment, not part of the package.

Run: ``.venv/bin/python experiments/patch_registration.py [SCENE ...] [--patches 20]
[--stiffness 0.1] [--no-refine]`` (default ``crane``; any bench scene; about a minute per scene
on 2 cores).

Why: the registration's ARAP term pulls every registered frame towards the template's rest
shape, while the performer's skin stretches and twists
(``registration_oracle.py --energies``: on crane the truth's ARAP energy against the template
is five times that of any registration's result). A model that bends freely between rigid
parts has a different bias. Here the template is cut into ``--patches`` patches by k-means on
its rest positions; every vertex moves by the blend of its patches' rigid motions (linear
blend skinning, weights: the patch labels diffused over 10 rings of the mesh); the patches'
motions are fitted by Gauss-Newton with point-to-plane pairs both ways (each vertex's nearest
point and each point's nearest vertex, normals agreeing, the registration's radius schedule)
and an embedded-deformation term ``sum |T_p(c_q) - T_q(c_q)|^2`` over neighbouring patches
``p, q`` (``c``: patch centroids) weighted ``--stiffness``. The registration's few softer ARAP
iterations follow (not with ``--no-refine``). Everything else is the method's own.

Measured (20,000 samples, correspondence mean / last frame, the method's registration ->
this one with 20 patches and stiffness 0.1): crane 0.0073 / 0.0120 -> 0.0069 / 0.0085
(registrations from the method's seeds and from the truth now end at the same state,
0.009-0.017 from the truth: the fit no longer depends on its seed, but its minimum is no
nearer the truth); but crane-50 0.0235 / 0.0308 -> 0.0321 / 0.0489, crane-90 0.0095 / 0.0150
-> 0.0134 / 0.0120, crane-130 0.0114 / 0.0177 -> 0.0165 / 0.0216, horse-gallop 0.0087 ->
0.0102, squash-ball 0.0226 / 0.0066 -> 0.128 / 0.161 and splitting-blob completeness-95
0.015 -> 0.16, at 2-8 times the registration's time; better on bending-arm (0.0202 / 0.0338
-> 0.0142 / 0.0226) and elephant-gallop (0.0244 / 0.0391 -> 0.0153 / 0.0149). With the
point-to-point targets of the ARAP registration instead: crane 0.0070 / 0.0088 (20 patches,
stiffness 0.02), 0.0152 / 0.0149 at stiffness 1; 10 patches 0.0139 / 0.0116, 40 0.0077 /
0.0098, 80 0.0094 / 0.0112. An upper bound on what such a model can hold: the best blend of
rigid patch motions fitted to crane's true positions (per patch and frame, by least squares)
is 0.0040 mean (0.0080 at the worst frame) from them with 20 patches and 0.0029 (0.0055) with
40, so the patches can represent the performer; it is the fit to the data that lands elsewhere.

It replaces ``register.ArapIcp.register`` for the run, so it is a diagnostic script.
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.sparse as sp
from scipy.cluster.vq import kmeans2
from scipy.spatial import cKDTree

from fourd import evaluate, synth
from fourd.bench import HELD_OUT_SCENES, PROTOCOL, STANDARD_SCENES
from fourd.geometry.neighbors import bucket_grid
from fourd.geometry.normals import vertex_normals
from fourd.methods import kinematic
from fourd.methods.kinematic import register
from fourd.methods.kinematic.register import GRID_CELL, _farthest_move, _nearest

DIFFUSION_RINGS = 10


def patch_model(rest: np.ndarray, edge_i: np.ndarray, edge_j: np.ndarray, patches: int):
    """Patch labels [N], blend weights (CSR [N, K]), patch centroids [K, 3] and neighbouring
    patch pairs [P, 2] of a template with rest positions ``rest`` [N, 3] and directed edges
    ``edge_i``, ``edge_j``."""
    n = len(rest)
    _, labels = kmeans2(rest, patches, minit="++", seed=0)
    k = int(labels.max()) + 1
    adjacency = sp.coo_matrix((np.ones(len(edge_i)), (edge_i, edge_j)), shape=(n, n)).tocsr()
    adjacency = ((adjacency + adjacency.T) > 0).astype(float)
    degree = np.maximum(np.asarray(adjacency.sum(axis=1)).ravel(), 1.0)
    weights = np.eye(k)[labels]
    for _ in range(DIFFUSION_RINGS):
        weights = 0.5 * weights + 0.5 * (adjacency @ weights) / degree[:, None]
    weights[weights < 0.01] = 0.0
    weights /= weights.sum(axis=1, keepdims=True)
    centroids = np.array([rest[labels == p].mean(axis=0) for p in range(k)])
    across = labels[edge_i] != labels[edge_j]
    pairs = np.unique(
        np.sort(np.stack([labels[edge_i][across], labels[edge_j][across]], 1), 1), axis=0
    )
    return labels, sp.csr_matrix(weights), centroids, pairs


def rotation(omega: np.ndarray) -> np.ndarray:
    """Rotation matrices [K, 3, 3] of the rotation vectors ``omega`` [K, 3] (Rodrigues)."""
    angle = np.linalg.norm(omega, axis=1)
    out = np.tile(np.eye(3), (len(omega), 1, 1))
    turning = angle > 1e-12
    axis = omega[turning] / angle[turning, None]
    cross = np.zeros((len(axis), 3, 3))
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    cross -= cross.transpose(0, 2, 1)
    sine = np.sin(angle[turning])[:, None, None]
    cosine = np.cos(angle[turning])[:, None, None]
    out[turning] = np.eye(3) + sine * cross + (1 - cosine) * cross @ cross
    return out


def blend(rest, weights, centroids, R, t):
    """Positions [N, 3] of the template under patch motions ``x -> R (x - c) + c + t``, and per
    weight entry the rotated offset from its patch's centroid [E, 3]."""
    entries = weights.tocoo()
    offsets = np.einsum("eab,eb->ea", R[entries.col], rest[entries.row] - centroids[entries.col])
    moved = entries.data[:, None] * (offsets + centroids[entries.col] + t[entries.col])
    out = np.zeros_like(rest)
    np.add.at(out, entries.row, moved)
    return out


def fitted_motions(rest, labels, centroids, positions):
    """Per patch the rigid motion (R [K, 3, 3], t [K, 3]) that best maps its rest vertices onto
    ``positions`` [N, 3] (least squares)."""
    k = len(centroids)
    R, t = np.tile(np.eye(3), (k, 1, 1)), np.zeros((k, 3))
    for p in range(k):
        mine = labels == p
        if mine.sum() < 3:
            continue
        source, target = rest[mine] - centroids[p], positions[mine]
        source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
        u, _, vt = np.linalg.svd((source - source_mean).T @ (target - target_mean))
        flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
        R[p] = vt.T @ flip @ u.T
        t[p] = target_mean - R[p] @ source_mean - centroids[p]
    return R, t


def make_register(patches: int, stiffness: float, refine: bool):
    """A replacement for ``ArapIcp.register`` fitting the patch model (see the module)."""
    arap_register = register.ArapIcp.register

    def patch_register(self, vertices, points, normals, *, iterations=None, start_radius=None,
                       previous=None):
        o = self.options
        iterations = o.iterations if iterations is None else iterations
        start_radius = o.start_radius if start_radius is None else start_radius
        if not hasattr(self, "_patches"):
            self._patches = patch_model(self.pre.rest, self.pre.edge_i, self.pre.edge_j, patches)
        labels, weights, centroids, pairs = self._patches
        rest = np.asarray(self.pre.rest, dtype=float)
        k = len(centroids)
        points_all, normals_all = points, normals
        points = np.ascontiguousarray(points[:: o.point_stride], dtype=float)
        normals = np.ascontiguousarray(normals[:: o.point_stride], dtype=float)
        if len(points) == 0:
            return np.asarray(vertices, dtype=float)
        R, t = fitted_motions(rest, labels, centroids, np.asarray(vertices, dtype=float))
        x = blend(rest, weights, centroids, R, t)
        cell = GRID_CELL * self.pre.edge_length
        point_grid, tree = bucket_grid(points, cell), cKDTree(points)
        to_point, point_lower = np.full(len(x), -1), np.zeros(len(x))
        to_vertex, vertex_lower = np.full(len(points), -1), np.zeros(len(points))
        regulariser = stiffness * len(x) / max(len(pairs), 1) / 3.0
        for it in range(iterations):
            radius = self._radius(it, iterations, start_radius)
            to_point, point_lower = _nearest(
                x, points, point_grid, tree, to_point, point_lower, radius
            )
            to_vertex, vertex_lower = _nearest(
                points, x, bucket_grid(x, cell), None, to_vertex, vertex_lower, radius
            )
            vn = vertex_normals(x, self.faces)
            first = np.flatnonzero(to_point >= 0)
            second = np.flatnonzero(to_vertex >= 0)
            pair_vertex = np.concatenate([first, to_vertex[second]])
            pair_point = np.concatenate([to_point[first], second])
            agree = np.einsum("ij,ij->i", vn[pair_vertex], normals[pair_point]) > o.normal_agreement
            pair_vertex, pair_point = pair_vertex[agree], pair_point[agree]
            along = normals[pair_point]
            residual = np.einsum("ij,ij->i", along, points[pair_point] - x[pair_vertex])
            # one row per pair: n . dx_v, dx_v = sum_p w_vp (omega_p x a_vp + dt_p)
            counts = np.diff(weights.indptr)[pair_vertex]
            row = np.repeat(np.arange(len(pair_vertex)), counts)
            entry = np.concatenate(
                [np.arange(weights.indptr[v], weights.indptr[v + 1]) for v in pair_vertex]
            ) if len(pair_vertex) else np.zeros(0, dtype=np.int64)
            patch, w = weights.indices[entry], weights.data[entry]
            offset = np.einsum("eab,eb->ea", R[patch], rest[pair_vertex[row]] - centroids[patch])
            normal = along[row]
            values = np.concatenate(
                [w[:, None] * np.cross(offset, normal), w[:, None] * normal], axis=1
            )
            columns = 6 * patch[:, None] + np.arange(6)[None, :]
            J = sp.csr_matrix(
                (values.ravel(), (np.repeat(row, 6), columns.ravel())),
                shape=(len(pair_vertex), 6 * k),
            )
            H = (J.T @ J).toarray()
            g = J.T @ residual
            for p, q in pairs:
                for u, v in ((p, q), (q, p)):
                    a = R[u] @ (centroids[v] - centroids[u])
                    gap = (centroids[v] + t[v]) - (a + centroids[u] + t[u])
                    D = np.zeros((3, 6 * k))
                    D[:, 6 * u : 6 * u + 3] = np.array(
                        [[0.0, a[2], -a[1]], [-a[2], 0.0, a[0]], [a[1], -a[0], 0.0]]
                    )
                    D[:, 6 * u + 3 : 6 * u + 6] = np.eye(3)
                    D[:, 6 * v + 3 : 6 * v + 6] -= np.eye(3)
                    H += regulariser * D.T @ D
                    g += regulariser * D.T @ gap
            H += 1e-8 * np.trace(H) / len(H) * np.eye(len(H))
            step = np.linalg.solve(H, g).reshape(k, 6)
            R, t = rotation(step[:, :3]) @ R, t + step[:, 3:]
            before, x = x, blend(rest, weights, centroids, R, t)
            move = _farthest_move(before, x)
            point_lower = np.maximum(point_lower - move, 0.0)
            vertex_lower = np.maximum(vertex_lower - move, 0.0)
        if refine and o.refine_iterations:
            x = arap_register(self, x, points_all, normals_all, iterations=0,
                              start_radius=o.end_radius, previous=previous)
        return x

    return patch_register


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["crane"])
    parser.add_argument("--patches", type=int, default=20)
    parser.add_argument("--stiffness", type=float, default=0.1)
    parser.add_argument("--no-refine", action="store_true")
    args = parser.parse_args()
    table = {s.key: s for s in STANDARD_SCENES + HELD_OUT_SCENES}
    original = register.ArapIcp.register
    patched = make_register(args.patches, args.stiffness, not args.no_refine)

    for key in args.scenes:
        scene = table[key]
        truth = synth.scene(scene.name, frames=scene.frames, seed=0, **scene.options)
        scans = synth.scan(truth, resolution=scene.resolution, seed=0, **{**PROTOCOL, **scene.scan})
        for name, replacement in (("arap", original), ("patches", patched)):
            register.ArapIcp.register = replacement
            try:
                result = kinematic.reconstruct(scans, kinematic.Options())
            finally:
                register.ArapIcp.register = original
            report = evaluate(result, truth, samples=20000)
            f = {
                k: float("nan") if report.get(k) is None else report[k]
                for k in ("correspondence_mean", "correspondence_last", "chamfer", "completeness_95")
            }
            print(f"{key} {name}: correspondence {f['correspondence_mean']:.4f} / "
                  f"{f['correspondence_last']:.4f}, Chamfer {f['chamfer']:.4f}, "
                  f"completeness-95 {f['completeness_95']:.4f}", flush=True)


if __name__ == "__main__":
    main()
