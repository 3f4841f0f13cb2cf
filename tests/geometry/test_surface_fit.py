"""fit_along_normals: vertices reach each frame's points along their normals only."""

import numpy as np
import trimesh

from fourd.geometry.surface_fit import fit_along_normals, normal_offsets


def _sphere(subdivisions=3):
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _sphere_points(count, radius, noise, seed, keep=None):
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    if keep is not None:
        directions = directions[keep(directions)]
    return directions * (radius + noise * rng.normal(size=(len(directions), 1)))


def test_a_shrunken_sphere_returns_to_its_points_without_sliding():
    vertices, faces = _sphere()
    frames = [_sphere_points(20000, 1.0, 0.005, seed) for seed in range(3)]
    shrunk = np.stack([0.96 * vertices] * 3)
    fit = fit_along_normals(shrunk, faces, frames, radius=0.05, reach=0.1)
    radii = np.linalg.norm(fit.vertices, axis=2)
    assert np.abs(radii - 1.0).max() < 0.008
    directions = fit.vertices / radii[..., None]
    # moved along the normal only: each vertex keeps its direction from the centre
    assert np.abs(directions - vertices[None]).max() < 1e-3
    assert fit.supported.all()
    assert np.allclose(fit.offsets, 0.04, atol=0.008)


def test_curvature_does_not_pull_vertices_to_the_chord():
    # a plane fit over a Gaussian of width r sits curvature * r^2 / 4 inside a sphere; the
    # quadric does not
    vertices, faces = _sphere()
    points = _sphere_points(20000, 1.0, 0.0, 0)
    offsets, support = normal_offsets(vertices, vertices, points, radius=0.1, reach=0.1)
    assert (support > 0).all()
    assert np.abs(offsets).max() < 0.0008  # a plane would give about 0.1^2 / 4 = 0.0025


def test_an_unseen_cap_follows_its_rim():
    vertices, faces = _sphere()
    frames = [_sphere_points(20000, 1.0, 0.0, 0, keep=lambda d: d[:, 2] < 0.7)]
    shifted = 0.97 * vertices[None]
    fit = fit_along_normals(shifted, faces, frames, radius=0.05, reach=0.1)
    cap = vertices[:, 2] > 0.8
    assert not fit.supported[0, cap].any()
    radii = np.linalg.norm(fit.vertices[0], axis=1)
    # the cap's offsets continue the rim's: no step at the edge of the data
    assert np.abs(radii[cap] - 1.0).max() < 0.01


def test_the_other_side_of_a_thin_part_does_not_pull():
    rng = np.random.default_rng(1)
    grid = rng.uniform(-1, 1, size=(30000, 2))
    gap = 0.06
    points = np.concatenate([np.c_[grid, np.zeros(len(grid))], np.c_[grid, np.full(len(grid), gap)]])
    vertices = np.c_[rng.uniform(-0.5, 0.5, size=(200, 2)), np.full(200, 0.012)]
    normals = np.tile([0.0, 0.0, 1.0], (200, 1))
    offsets, _ = normal_offsets(vertices, normals, points, radius=0.03, reach=0.05)
    # the nearer sheet (0.012 below) wins over the farther one (0.048 above)
    assert np.abs(offsets + 0.012).max() < 0.003
