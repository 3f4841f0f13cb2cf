import numpy as np
import pytest
import trimesh

from fourd.geometry.closest_point import MeshLocator, closest_on_triangles, closest_points_on_mesh


def _brute_force(vertices, faces, points):
    """The closest point over every triangle: distances [M]."""
    corners = vertices[faces]
    m, f = len(points), len(faces)
    repeated = np.repeat(points, f, axis=0)
    tiled = np.tile(corners, (m, 1, 1))
    bary = closest_on_triangles(repeated, tiled[:, 0], tiled[:, 1], tiled[:, 2])
    closest = np.einsum("sk,skd->sd", bary, tiled)
    return np.linalg.norm(closest - repeated, axis=1).reshape(m, f).min(axis=1)


def test_points_near_a_bumpy_sphere_find_the_true_closest_point():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(0)
    vertices = sphere.vertices * (1.0 + 0.05 * rng.standard_normal((len(sphere.vertices), 1)))
    edge = float(np.median(sphere.edges_unique_length))
    points = vertices[rng.integers(0, len(vertices), 400)] + rng.normal(scale=edge, size=(400, 3))
    found = closest_points_on_mesh(vertices, sphere.faces, points)
    np.testing.assert_allclose(found.distances, _brute_force(vertices, sphere.faces, points), atol=1e-12)
    # the point, its distance, its triangle and barycentric coordinates agree with each other
    np.testing.assert_allclose(np.linalg.norm(found.points - points, axis=1), found.distances, atol=1e-12)
    on_triangle = np.einsum("mk,mkd->md", found.barycentric, vertices[sphere.faces[found.triangle]])
    np.testing.assert_allclose(on_triangle, found.points, atol=1e-12)
    assert (found.barycentric >= 0).all() and np.allclose(found.barycentric.sum(axis=1), 1.0)


def test_a_mesh_with_fewer_triangles_than_candidates_and_no_points():
    square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    found = closest_points_on_mesh(square, faces, [[0.9, 0.1, -2.0]])
    assert found.distances.tolist() == [2.0] and found.triangle.tolist() == [0]
    assert len(closest_points_on_mesh(square, faces, np.zeros((0, 3))).triangle) == 0
    with pytest.raises(ValueError, match="no faces"):
        closest_points_on_mesh(square, np.zeros((0, 3), dtype=int), [[0.0, 0, 0]])


def test_zero_area_triangles_give_their_edges_closest_point_not_nan():
    rng = np.random.default_rng(1)
    points = rng.normal(size=(300, 3))
    a = np.zeros((300, 3))
    # collinear corners, and two corners at one place
    for b, c in (([1.0, 0, 0], [2.0, 0, 0]), ([1.0, 0, 0], [1.0, 0, 0]), ([0.0, 0, 0], [0.0, 1, 0])):
        bary = closest_on_triangles(points, a, np.tile(b, (300, 1)), np.tile(c, (300, 1)))
        assert np.isfinite(bary).all() and (bary >= 0).all() and np.allclose(bary.sum(axis=1), 1.0)
        found = bary @ np.array([[0.0, 0, 0], b, c])
        # the closest point of the segment the corners span
        end = np.array(c if np.linalg.norm(c) >= np.linalg.norm(b) else b)
        t = np.clip(points @ end / (end @ end), 0.0, 1.0)
        np.testing.assert_allclose(found, t[:, None] * end, atol=1e-12)


def test_the_compiled_locator_finds_what_the_vectorised_search_finds():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(2)
    vertices = sphere.vertices * (1.0 + 0.05 * rng.standard_normal((len(sphere.vertices), 1)))
    edge = float(np.median(sphere.edges_unique_length))
    points = vertices[rng.integers(0, len(vertices), 400)] + rng.normal(scale=edge, size=(400, 3))
    locator = MeshLocator(vertices, sphere.faces)
    for batch in (points, points[:7] + 0.1 * edge):  # one tree, several queries
        found, expected = locator.closest(batch), closest_points_on_mesh(vertices, sphere.faces, batch)
        np.testing.assert_allclose(found.distances, expected.distances, atol=1e-12)
        np.testing.assert_allclose(found.points, expected.points, atol=1e-12)
        on_triangle = np.einsum("mk,mkd->md", found.barycentric, vertices[sphere.faces[found.triangle]])
        np.testing.assert_allclose(on_triangle, found.points, atol=1e-12)
    # zero-area triangles (collinear corners, two corners at one place: divisions by zero
    # on the way) give their edges' closest point, as the vectorised search does
    corners = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 0], [0, 1, 0]])
    points = np.random.default_rng(3).normal(size=(300, 3))
    for triangle in ([0, 1, 2], [0, 1, 3], [0, 0, 4], [1, 1, 1]):
        found = MeshLocator(corners, [triangle]).closest(points)
        expected = closest_points_on_mesh(corners, [triangle], points)
        assert np.isfinite(found.points).all() and (found.triangle == 0).all()
        np.testing.assert_allclose(found.distances, expected.distances, atol=1e-12)
    line = corners[:3]
    with pytest.raises(ValueError, match="no faces"):
        MeshLocator(line, np.zeros((0, 3), dtype=int))
