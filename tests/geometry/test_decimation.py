"""Quadric decimation and the carrying of a coarse mesh's displacements back to the fine one."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from fourd.geometry.boundary_loops import boundary_edges
from fourd.geometry.decimation import decimate
from fourd.geometry.meshes import median_edge_length


def _sphere():
    sphere = trimesh.creation.icosphere(subdivisions=5)
    return np.asarray(sphere.vertices), np.asarray(sphere.faces)


def test_a_sphere_keeps_its_shape_at_a_quarter_of_its_faces():
    vertices, faces = _sphere()
    coarse = decimate(vertices, faces, 0.75)
    assert 0.2 < len(coarse.faces) / len(faces) < 0.3
    mesh = trimesh.Trimesh(coarse.vertices, coarse.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert np.abs(np.linalg.norm(coarse.vertices, axis=1) - 1.0).max() < 0.01
    ratio = median_edge_length(coarse.vertices, coarse.faces) / median_edge_length(vertices, faces)
    assert 1.6 < ratio < 2.4  # measured: 2.0
    # outward, as the input
    assert np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center).min() > 0


def test_the_border_of_a_hole_stays():
    vertices, faces = _sphere()
    cap = vertices[faces].mean(axis=1)[:, 2] > 0.8
    coarse = decimate(vertices, faces[~cap], 0.75)
    rim = coarse.vertices[np.unique(boundary_edges(coarse.faces, len(coarse.vertices)))]
    assert len(rim) > 10
    edge = median_edge_length(vertices, faces)
    # on the sphere and at the cut, to a small part of an edge (measured: 0.03 edges off the sphere)
    assert np.abs(np.linalg.norm(rim, axis=1) - 1.0).max() < 0.1 * edge
    assert np.abs(rim[:, 2] - 0.8).max() < 2.0 * edge


def test_a_translation_is_carried_exactly_and_a_small_turn_nearly():
    vertices, faces = _sphere()
    coarse = decimate(vertices, faces, 0.75)
    shift = np.array([0.3, -0.1, 0.2])
    np.testing.assert_allclose(coarse.carry(coarse.vertices + shift), np.broadcast_to(shift, vertices.shape),
                               atol=1e-12)
    angle = 0.05
    turn = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    carried = vertices + coarse.carry(coarse.vertices @ turn.T)
    error = np.linalg.norm(carried - vertices @ turn.T, axis=1).max()
    edge = median_edge_length(vertices, faces)
    assert error < 0.1 * edge  # measured: 0.065 edges (the turn moves points up to 1.3 edges)


def test_a_reduction_outside_the_unit_interval_is_refused():
    vertices, faces = _sphere()
    with pytest.raises(ValueError, match="reduction"):
        decimate(vertices, faces, 1.0)
