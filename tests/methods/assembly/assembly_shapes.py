"""Source/target pairs for the assembly method's tests: a mesh and a rigidly moved copy, and
two frames of a generated scene each remeshed on its own (with the true correspondence)."""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from fourd.methods.assembly import Anchors, anchors_at_vertices


class Pair(NamedTuple):
    source_vertices: np.ndarray
    source_faces: np.ndarray
    target_vertices: np.ndarray
    target_faces: np.ndarray
    anchors: Anchors
    truth: np.ndarray  # [N, 3] the true image of every source vertex on the target
    edge: float  # the source's median edge length
    back: np.ndarray  # [M, 3] the true image of every target vertex on the source


def _median_edge(vertices, faces) -> float:
    return float(np.median(np.linalg.norm(vertices[faces] - vertices[np.roll(faces, 1, axis=1)], axis=2)))


def spread(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` indices of ``points`` spread evenly (farthest-point sampling from point 0),
    sorted: anchors as the method redistributes them (thesis 5.4.1)."""
    chosen = [0]
    distance = np.linalg.norm(points - points[0], axis=1)
    for _ in range(count - 1):
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return np.sort(np.array(chosen, dtype=np.int64))


@cache
def rigid_copy(subdivisions: int = 3, fraction: float = 0.12) -> Pair:
    """A bumpy sphere and a rotated, shifted copy; anchors: ``fraction`` of the vertices,
    spread evenly, matched to themselves."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    unit = np.asarray(sphere.vertices)
    vertices = unit * (1.0 + 0.1 * np.sin(3.0 * unit[:, [0]]) * np.cos(2.0 * unit[:, [1]]))
    faces = np.asarray(sphere.faces, dtype=np.int64)
    moved = vertices @ Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix().T + [1.0, 2.0, 3.0]
    ids = spread(vertices, int(fraction * len(vertices)))
    return Pair(vertices, faces, moved, faces, anchors_at_vertices(ids, ids, faces), moved,
                _median_edge(vertices, faces), vertices)


@cache
def remeshed_frames(name: str = "bending-arm", frame: int = 3, resolution: int = 48) -> Pair:
    """Frames 0 and ``frame`` of a scene (8 frames), each remeshed on its own at the rays'
    spacing of ``resolution``; anchors: 3% of the source vertices, spread evenly, matched to
    the closest target points of their true images."""
    from fourd.synth.remesh import remesh_surface
    from fourd.synth.scenes import scene

    truth = scene(name, frames=8)
    spacing = 1.2 * truth.diagonal() / resolution
    v0, f0 = truth.frame(0)
    v1, f1 = truth.frame(frame)
    source = remesh_surface(v0, f0, spacing=spacing, offset=[0.1, 0.5, 0.3])
    target = remesh_surface(v1, f1, spacing=spacing, offset=[0.7, 0.2, 0.9])
    true = np.einsum("nk,nkd->nd", source.barycentric, v1[f1[source.truth_faces]])
    back = np.einsum("nk,nkd->nd", target.barycentric, v0[f0[target.truth_faces]])
    ids = spread(source.vertices, int(0.03 * len(source.vertices)))
    mesh = trimesh.Trimesh(target.vertices, target.faces, process=False)
    closest, _, triangle = trimesh.proximity.closest_point(mesh, true[ids])
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[triangle], closest)
    anchors = Anchors(ids, triangle.astype(np.int64), bary)
    return Pair(source.vertices, source.faces, target.vertices, target.faces, anchors, true,
                _median_edge(source.vertices, source.faces), back)


def true_map(pair: Pair) -> tuple[np.ndarray, np.ndarray]:
    """The true map as target triangles ``[N]`` and barycentric coordinates ``[N, 3]``: the
    target points closest to the true images (which lie on the truth, not on the target's
    triangles)."""
    mesh = trimesh.Trimesh(pair.target_vertices, pair.target_faces, process=False)
    closest, _, triangle = trimesh.proximity.closest_point(mesh, pair.truth)
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[triangle], closest)
    return triangle.astype(np.int64), np.clip(bary, 0.0, None) / np.clip(bary, 0.0, None).sum(axis=1, keepdims=True)


def slid_map(pair: Pair, noise: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The true map with every point slid along the target by a random tangent step (normal,
    ``noise`` source edges per axis)."""
    from fourd.geometry.surface_walk import walk_on_surface

    faces, bary = true_map(pair)
    step = np.random.default_rng(seed).normal(scale=noise * pair.edge, size=(len(faces), 3))
    walked = walk_on_surface(pair.target_vertices, pair.target_faces, faces, bary, step)
    return walked.faces, walked.barycentric
