"""Surface samples and exact closest points, checked against trimesh."""

from __future__ import annotations

import numpy as np
import trimesh

from fourd.metrics.sampling import (
    bind_to_surface,
    bound_positions,
    closest_on_triangles,
    face_areas,
    sample_points,
    sample_surface,
)


def test_samples_lie_on_the_mesh_and_follow_area():
    box = trimesh.creation.box(extents=[4.0, 1.0, 1.0])
    samples = sample_surface(box.vertices, box.faces, 20000, np.random.default_rng(0))
    assert samples.points.shape == (20000, 3)
    corners = box.vertices[box.faces[samples.faces]]
    rebuilt = np.einsum("sk,skd->sd", samples.barycentric, corners)
    assert np.abs(rebuilt - samples.points).max() < 1e-12
    assert np.all(samples.barycentric >= -1e-12)
    # The two 1 x 1 end caps hold 2 / 18 of the area.
    on_caps = np.isclose(np.abs(samples.points[:, 0]), 2.0)
    assert abs(on_caps.mean() - 2 / 18) < 0.01
    again = sample_surface(box.vertices, box.faces, 20000, np.random.default_rng(0))
    assert np.array_equal(again.points, samples.points)
    assert face_areas(box.vertices, box.faces).sum() == np.float64(18.0)


def test_point_sets_are_subsampled():
    points = np.random.default_rng(1).normal(size=(500, 3))
    few = sample_points(points, 100, np.random.default_rng(0))
    assert len(few.points) == 100 and len(np.unique(few.vertices)) == 100
    assert np.array_equal(points[few.vertices], few.points)
    everything = sample_surface(points, np.zeros((0, 3), dtype=int), 1000, np.random.default_rng(0))
    assert len(everything.points) == 500


def test_closest_points_match_trimesh():
    rng = np.random.default_rng(2)
    mesh = trimesh.creation.icosphere(2)
    mesh.vertices += rng.normal(scale=0.05, size=mesh.vertices.shape)  # irregular triangles
    queries = rng.normal(size=(800, 3)) * 1.5
    samples = sample_surface(mesh.vertices, mesh.faces, 20000, np.random.default_rng(3))
    binding = bind_to_surface(queries, mesh.vertices, mesh.faces, samples)
    _, expected, _ = trimesh.proximity.closest_point(mesh, queries)
    assert np.all(binding.distances >= expected - 1e-9)
    assert np.mean(binding.distances - expected < 1e-9) > 0.99
    assert np.abs(bound_positions(binding, mesh.vertices, mesh.faces) - binding.points).max() < 1e-12
    # Every Voronoi region of a single triangle, against brute force over a fine grid on it.
    a, b, c = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.2, 0.8, 0])
    points = rng.uniform(-1, 2, size=(500, 3))
    bary = closest_on_triangles(points, *(np.repeat(v[None], 500, 0) for v in (a, b, c)))
    found = np.linalg.norm(bary @ np.stack([a, b, c]) - points, axis=1)
    u, v = np.meshgrid(np.linspace(0, 1, 101), np.linspace(0, 1, 101))
    keep = u + v <= 1
    grid = np.outer(1 - u[keep] - v[keep], a) + np.outer(u[keep], b) + np.outer(v[keep], c)
    brute = np.linalg.norm(points[:, None] - grid[None], axis=2).min(axis=1)
    assert np.all(found <= brute + 1e-12) and np.all(found >= brute - 0.01)


def test_binding_follows_a_moving_mesh():
    mesh = trimesh.creation.icosphere(2)
    frames = np.stack([mesh.vertices * (1 + 0.1 * t) + [t, 0, 0] for t in range(3)])
    samples = sample_surface(mesh.vertices, mesh.faces, 5000, np.random.default_rng(0))
    binding = bind_to_surface(mesh.vertices * 1.01, mesh.vertices, mesh.faces, samples)
    moved = bound_positions(binding, frames, mesh.faces)
    assert moved.shape == (3, len(mesh.vertices), 3)
    assert np.abs(moved[2] - (binding.points * 1.2 + [2, 0, 0])).max() < 1e-9
