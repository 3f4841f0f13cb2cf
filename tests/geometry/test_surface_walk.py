"""Walking points along a mesh: straight lines on a flat sheet, close to great circles on a
sphere, stopped at the boundary, face neighbours consistent with the shared edges."""

from __future__ import annotations

import numpy as np
import trimesh

from fourd.geometry.surface_walk import face_neighbours, plane_barycentric, walk_on_surface


def _grid(n=11):
    x, y = np.meshgrid(np.linspace(0.0, 1.0, n), np.linspace(0.0, 1.0, n))
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    index = np.arange(n * n).reshape(n, n)
    a, b, c, d = index[:-1, :-1].ravel(), index[:-1, 1:].ravel(), index[1:, 1:].ravel(), index[1:, :-1].ravel()
    return vertices, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _starts(faces, count, rng):
    return rng.integers(len(faces), size=count), rng.dirichlet([1.0, 1.0, 1.0], size=count)


def test_face_neighbours_share_the_edge_opposite_the_corner():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    faces = np.asarray(sphere.faces)
    neighbours = face_neighbours(faces)
    assert (neighbours >= 0).all()  # closed
    for k in range(3):
        edge = np.sort(faces[:, [(k + 1) % 3, (k + 2) % 3]], axis=1)
        other = faces[neighbours[:, k]]
        assert ((other[:, :, None] == edge[:, None, :]).any(axis=1)).all()
        back = neighbours[neighbours[:, k]]
        assert (back == np.arange(len(faces))[:, None]).any(axis=1).all()
    vertices, grid = _grid(3)
    assert (face_neighbours(grid) < 0).sum() == 8  # the square's boundary edges


def test_a_walk_on_a_flat_sheet_is_a_straight_line_and_stops_at_the_border():
    vertices, faces = _grid()
    rng = np.random.default_rng(0)
    face, bary = _starts(faces, 500, rng)
    start = np.einsum("kc,kcd->kd", bary, vertices[faces[face]])
    step = rng.normal(scale=0.3, size=(500, 3))
    step[:, 2] = 0.5  # the normal part is dropped
    walked = walk_on_surface(vertices, faces, face, bary, step)
    end = start + step * [1.0, 1.0, 0.0]
    inside = ((end[:, :2] > 0.0) & (end[:, :2] < 1.0)).all(axis=1)
    assert inside.sum() > 200 and (~inside).sum() > 50
    assert np.abs(walked.points[inside] - end[inside]).max() < 1e-12
    assert not walked.stopped[inside].any() and walked.stopped[~inside].all()
    # a point stopped at the border lies on it, on the line it walked
    on_border = walked.points[~inside, :2]
    assert (np.minimum(on_border, 1.0 - on_border).min(axis=1) < 1e-12).all()
    assert ((on_border >= -1e-12) & (on_border <= 1.0 + 1e-12)).all()
    np.testing.assert_allclose(walked.barycentric.sum(axis=1), 1.0)
    assert (walked.barycentric >= 0).all()
    np.testing.assert_allclose(
        np.einsum("kc,kcd->kd", walked.barycentric, vertices[faces[walked.faces]]), walked.points
    )


def test_a_walk_on_a_sphere_follows_the_great_circle():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    rng = np.random.default_rng(1)
    face, bary = _starts(faces, 500, rng)
    start = np.einsum("kc,kcd->kd", bary, vertices[faces[face]])
    direction = rng.normal(size=(500, 3))
    direction -= np.einsum("kd,kd->k", direction, start)[:, None] * start
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    walked = walk_on_surface(vertices, faces, face, bary, 0.5 * direction)
    circle = np.cos(0.5) * start + np.sin(0.5) * direction
    # measured: 0.024 at most (the polyhedron's edges are 0.077 long)
    assert np.linalg.norm(walked.points - circle, axis=1).max() < 0.04
    assert not walked.stopped.any()


def test_plane_barycentric_is_nan_on_a_degenerate_triangle():
    corners = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]])
    bary = plane_barycentric(corners, np.array([[0.25, 0.25, 3.0], [0.5, 0.0, 0.0]]))
    np.testing.assert_allclose(bary[0], [0.5, 0.25, 0.25])
    assert np.isnan(bary[1]).all()


def test_a_displacement_at_the_rounding_level_leaves_a_point_at_a_vertex_where_it_is():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    rng = np.random.default_rng(2)
    face = rng.integers(len(faces), size=300)
    bary = np.eye(3)[rng.integers(3, size=300)]  # at a corner: noise would spin it round
    walked = walk_on_surface(vertices, faces, face, bary, rng.normal(scale=1e-15, size=(300, 3)))
    assert not walked.stopped.any()
    np.testing.assert_array_equal(walked.faces, face)
    np.testing.assert_array_equal(walked.barycentric, bary)
