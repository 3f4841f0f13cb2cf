"""Densified sparse scans (:mod:`fourd.geometry.densify`)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from fourd.geometry.densify import densify_points


def _sphere(count, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(count, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p


def test_a_sparse_sphere_is_sampled_on_its_surface_at_the_density_asked():
    points = _sphere(700)
    dense, normals = densify_points(points, points, density=5000 / (4 * np.pi))
    assert 4000 < len(dense) < 5500
    assert np.abs(np.linalg.norm(dense, axis=1) - 1.0).max() < 0.03
    assert np.einsum("ij,ij->i", dense, normals).min() > 0.9  # outward unit normals
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    # the sphere is covered more finely than by the scan (a gap wider than the surface's clip
    # distance stays a hole: nothing is made up where no point is)
    probes = _sphere(20000, seed=1)
    assert np.median(cKDTree(dense).query(probes)[0]) < 0.6 * np.median(cKDTree(points).query(probes)[0])


def test_an_open_scan_stays_open_and_keeps_its_boundary():
    rng = np.random.default_rng(2)
    radius = np.sqrt(rng.random(900))
    angle = rng.random(900) * 2 * np.pi
    disk = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros(900)], axis=1)
    up = np.tile([0.0, 0.0, 1.0], (900, 1))
    dense, normals = densify_points(disk, up, density=4000 / np.pi)
    assert len(dense) > 2500
    assert np.abs(dense[:, 2]).max() < 1e-6 and normals[:, 2].min() > 0.999
    spacing = np.median(cKDTree(disk).query(disk, k=2)[0][:, 1])
    # the surface reaches past the last points by at most its clip distance (2 spacings)
    assert np.linalg.norm(dense[:, :2], axis=1).max() < 1.0 + 2.5 * spacing


def test_dense_enough_frames_come_back_unchanged():
    points = _sphere(3000)
    same, normals = densify_points(points, points, density=1000 / (4 * np.pi))
    assert same is points and normals is points
    with pytest.raises(ValueError, match="density"):
        densify_points(points, points, density=0.0)

