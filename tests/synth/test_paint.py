import numpy as np
import pytest

from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.synth.paint import barycentric, hit_albedo, hit_normals, truth_paint
from fourd.synth.scenes import scene


def test_barycentric_reconstructs_points():
    rng = np.random.default_rng(0)
    corners = rng.normal(size=(50, 3, 3))
    weights = rng.dirichlet(np.ones(3), size=50)
    points = np.einsum("pk,pkj->pj", weights, corners)
    np.testing.assert_allclose(barycentric(points, corners), weights, atol=1e-9)


def test_albedo_of_a_material_point_is_the_same_in_every_frame():
    truth = scene("bending-arm", frames=3)
    paint = truth_paint(truth, "cloth", seed=2)
    rng = np.random.default_rng(1)
    triangle = rng.integers(0, len(truth.faces), 400)
    weights = rng.dirichlet(np.ones(3), size=400)
    colors = []
    for t in range(3):
        vertices = truth.vertices[t]
        points = np.einsum("pk,pkj->pj", weights, vertices[truth.faces[triangle]])
        colors.append(hit_albedo(paint, vertices, truth.faces, triangle, points))
    np.testing.assert_allclose(colors[0], colors[2], atol=1e-9)  # moves with the material
    # ... while the colour found at the same place in space changes as the arm bends
    moved = np.einsum("pk,pkj->pj", weights, truth.vertices[2][truth.faces[triangle]])
    from fourd.synth.albedo import albedo

    in_space = albedo(moved, "cloth", bounds=paint.bounds, seed=2)
    assert np.abs(in_space - colors[2]).max(axis=1).mean() > 0.05


def test_normals_face_the_viewer():
    truth = scene("squash-ball", frames=1)
    vertices, faces = truth.frame(0)
    normals = vertex_normals(vertices, faces)
    triangle = np.arange(0, len(faces), 97)
    points = vertices[faces[triangle]].mean(axis=1)
    outward = hit_normals(normals, vertices, faces, triangle, points, -points)  # rays inward
    assert np.all(np.einsum("ij,ij->i", outward, points) > 0)
    inward = hit_normals(normals, vertices, faces, triangle, points, points)  # seen from inside
    assert np.all(np.einsum("ij,ij->i", inward, points) < 0)


def test_paint_needs_a_kind_and_a_truth():
    with pytest.raises(InputError):
        truth_paint(scene("squash-ball", frames=1), None)
    with pytest.raises(InputError):
        truth_paint("not a truth", "skin")
