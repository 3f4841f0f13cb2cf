import numpy as np
import trimesh

from fourd.geometry.neighbors import knn, point_spacing
from fourd.geometry.normals import estimate_normals, pca_normals, vertex_normals


def _sphere(count, seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(count, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    return points + rng.normal(size=points.shape) * noise


def test_pca_normals_of_a_plane_are_its_normal():
    rng = np.random.default_rng(1)
    points = np.c_[rng.uniform(size=(500, 2)), np.zeros(500)]
    normals, flatness = pca_normals(points, 12)
    assert np.all(np.abs(normals[:, 2]) > 0.999)
    assert np.all(flatness > 0.99)


def test_propagation_orients_a_closed_surface_outwards():
    points = _sphere(3000, noise=0.002)
    normals = estimate_normals(points).normals
    assert np.mean(np.einsum("ij,ij->i", normals, points) > 0.9) > 0.99


def test_sensor_orientation_on_visible_points():
    points = _sphere(20000, seed=2)
    angles = 0.3 + np.arange(3) * 2 * np.pi / 3
    sensors = np.c_[4 * np.cos(angles), np.full(3, 1.0), 4 * np.sin(angles)]
    visible = (np.einsum("pkj,pj->pk", sensors[None] - points[:, None], points) > 0.1).any(axis=1)
    points = points[visible] + np.random.default_rng(3).normal(size=(visible.sum(), 3)) * 0.003
    normals = estimate_normals(points, sensors=sensors).normals
    assert np.mean(np.einsum("ij,ij->i", normals, points) > 0) > 0.995


def test_spacing_and_knn_scale_with_the_data():
    points = _sphere(2000, seed=4)
    assert np.isclose(point_spacing(points * 10), 10 * point_spacing(points), rtol=1e-9)
    distances, indices = knn(points, 5)
    assert distances.shape == (2000, 5) and np.all(indices != np.arange(2000)[:, None])
    assert np.all(np.diff(distances, axis=1) >= 0)


def test_scanned_crane_normals_agree_with_the_truth():
    import pytest
    import trimesh
    from scipy.spatial import cKDTree

    from fourd.synth import scene
    from fourd.synth.data import shared_data_dir
    from fourd.synth.scanner import SURFACE, camera_rig, scan_frame

    if shared_data_dir() is None:
        pytest.skip("../shared/data is not available")
    truth = scene("crane", frames=6)
    scan = scan_frame(truth, 5)
    points = scan.points[scan.label == SURFACE]
    mesh = trimesh.Trimesh(truth.vertices[5], truth.faces, process=False)
    true_normals = mesh.vertex_normals[cKDTree(mesh.vertices).query(points)[1]]
    sensors = camera_rig(truth.bounds(), 3).positions
    normals = estimate_normals(points, sensors=sensors).normals
    assert np.mean(np.einsum("ij,ij->i", normals, true_normals) > 0) > 0.99


def test_closed_form_smallest_eigenvector_matches_lapack():
    from fourd.geometry.normals import _smallest_eigenpair

    rng = np.random.default_rng(5)
    cases = [a @ a.T for a in rng.normal(size=(200, 3, 3))]
    cases += [np.diag([1.0, 1.0, 1e-9]), np.diag([2.0, 1e-12, 2.0]), np.eye(3), np.zeros((3, 3))]
    flat = rng.normal(size=(50, 3)) * [1.0, 1.0, 1e-6]  # a plane: repeated large eigenvalues
    cases.append(flat.T @ flat)
    for C in cases:
        out = np.empty(3)
        value = _smallest_eigenpair(np.ascontiguousarray(C), out)
        values, vectors = np.linalg.eigh(C)
        assert np.isclose(value, values[0], atol=1e-9 * max(values[-1], 1.0))
        assert np.isclose(np.linalg.norm(out), 1.0)
        if values[1] - values[0] > 1e-6 * max(values[-1], 1e-300):
            assert abs(out @ vectors[:, 0]) > 1 - 1e-8
        else:
            # degenerate smallest eigenvalue: any unit vector of that eigenspace
            assert np.linalg.norm(C @ out - values[0] * out) < 1e-6 * max(values[-1], 1.0)


def test_propagation_orients_every_separate_part_outwards():
    from fourd.geometry.normals import orient_by_propagation

    a, b = _sphere(2000, seed=6), _sphere(1500, seed=7) * 0.5
    points = np.concatenate([a, b + [5.0, 0.0, 0.0]])
    outward = np.concatenate([a, b / 0.5])
    _, indices = knn(points, 12)
    unoriented = pca_normals(points, 12, indices=indices).normals
    flips = np.where(np.random.default_rng(8).random(len(points)) < 0.5, -1.0, 1.0)
    normals = orient_by_propagation(points, unoriented * flips[:, None], indices)
    facing = np.einsum("ij,ij->i", normals, outward)
    assert np.mean(facing[:2000] > 0.9) > 0.99 and np.mean(facing[2000:] > 0.9) > 0.99


def test_vertex_normals_of_one_frame_and_of_frames_agree_and_point_outwards():
    import trimesh

    from fourd.geometry.normals import vertex_normals

    sphere = trimesh.creation.icosphere(subdivisions=3)
    rng = np.random.default_rng(2)
    vertices = np.asarray(sphere.vertices) * (1.0 + 0.05 * rng.normal(size=(len(sphere.vertices), 1)))
    # an unused vertex, which gets (0, 0, 1)
    vertices = np.vstack([vertices, [[5.0, 5.0, 5.0]]])
    faces = np.asarray(sphere.faces)
    one = vertex_normals(vertices, faces)
    many = vertex_normals(np.stack([vertices, 2.0 * vertices]), faces)
    np.testing.assert_allclose(one, many[0], atol=1e-15)
    np.testing.assert_allclose(one, many[1], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(one, axis=1), 1.0)
    np.testing.assert_array_equal(one[-1], [0.0, 0.0, 1.0])
    radial = vertices[:-1] / np.linalg.norm(vertices[:-1], axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", one[:-1], radial).min() > 0.8


def test_vertex_normals_area_weighted():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    normals = vertex_normals(sphere.vertices, sphere.faces)
    assert (
        np.min(np.sum(normals * sphere.vertices, axis=1)) >= 0.999
    )  # outward radial on a unit sphere
    # one big and one tiny triangle sharing vertex 0: the big one dominates
    vertices = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 0.1], [0.1, 0, 0.0]], float)
    faces = np.array([[0, 1, 2], [0, 3, 4]])
    n = vertex_normals(vertices, faces)
    assert n[0, 2] > 0.99
    stacked = vertex_normals(np.stack([sphere.vertices, 2 * sphere.vertices]), sphere.faces)
    assert np.allclose(stacked[0], normals) and np.allclose(stacked[1], normals)
