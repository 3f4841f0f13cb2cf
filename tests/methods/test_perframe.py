import dataclasses

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import fourd
from fourd.animation import MeshSequence
from fourd.errors import InputError
from fourd.methods import method_options
from fourd.methods.perframe import (
    MIN_FRAMES,
    Options,
    cell_corner_minimum,
    oriented_normals,
    reconstruct,
    reconstruct_frame,
    taubin_smooth,
    voxel_average,
)
from fourd.sequence import Frame, PointCloudSequence

NOISE = 0.007  # 0.2% of the sphere's bounding-box diagonal, like the standard scan


def _fibonacci_sphere(count, radius=1.0):
    index = np.arange(count) + 0.5
    phi = np.arccos(1 - 2 * index / count)
    theta = np.pi * (1 + 5**0.5) * index
    return radius * np.stack(
        [np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1
    )


def _noisy_sphere(seed=0, count=3000, outliers=0.02, noise=NOISE):
    rng = np.random.default_rng(seed)
    points = _fibonacci_sphere(count) + rng.normal(scale=noise, size=(count, 3))
    extra = rng.uniform(-1.0, 1.0, size=(int(outliers * count), 3))
    return np.concatenate([points, extra])


def _sheet(seed=0, side=50, noise=0.003):
    rng = np.random.default_rng(seed)
    axis = np.linspace(-1.0, 1.0, side)
    x, y = np.meshgrid(axis, axis, indexing="ij")
    x = x.ravel() + rng.uniform(-0.01, 0.01, x.size)
    y = y.ravel() + rng.uniform(-0.01, 0.01, y.size)
    z = 0.15 * np.sin(2.0 * x) * np.cos(1.5 * y) + rng.normal(scale=noise, size=x.size)
    return np.stack([x, y, z], axis=1)


def _sheet_height(points):
    return 0.15 * np.sin(2.0 * points[:, 0]) * np.cos(1.5 * points[:, 1])


def test_noisy_sphere_is_closed_accurate_and_complete():
    points = _noisy_sphere()
    vertices, faces = reconstruct_frame(Frame(points))
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight
    assert mesh.body_count == 1
    assert mesh.volume > 0  # outward-wound
    radius = np.linalg.norm(vertices, axis=1)
    # Smoothing averages the noise away; the grid adds at most a fraction of a cell.
    assert np.abs(radius - 1.0).mean() < NOISE
    assert np.abs(radius - 1.0).max() < 2 * NOISE + 0.02
    # Completeness: every point of the true sphere is close to the output.
    truth = _fibonacci_sphere(5000)
    gaps, _ = cKDTree(vertices).query(truth)
    assert gaps.max() < 0.05


def test_open_sheet_stays_open():
    points = _sheet()
    frame = Frame(points, sensors=np.array([[0.0, 0.0, 5.0]]))
    vertices, faces = reconstruct_frame(frame)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 1).sum() > 50  # a boundary exists
    assert mesh.body_count == 1
    # No surface away from the data: close to the true sheet and not past its border.
    assert np.abs(vertices[:, 2] - _sheet_height(vertices)).max() < 0.03
    spacing = 2.0 / 49
    assert np.abs(vertices[:, :2]).max() < 1.0 + 3 * spacing
    # Normals face the sensor (upwards).
    assert np.mean(mesh.face_normals[:, 2] > 0) > 0.99
    # The output covers the sheet.
    gaps, _ = cKDTree(vertices).query(points)
    assert gaps.max() < 2 * spacing


def test_open_sheet_without_sensors_stays_open():
    vertices, faces = reconstruct_frame(Frame(_sheet(seed=1)))
    assert len(faces) > 1000
    assert np.abs(vertices[:, 2] - _sheet_height(vertices)).max() < 0.03


def test_a_sheet_with_gaps_has_no_pinched_vertex():
    """Half the points dropped at random: cells kept around the rest touch at edges and
    corners (two pinches on this sheet before), and each pinch gets a copy per fan."""
    from fourd.geometry.fans import pinched_vertices
    from fourd.metrics.topology import topology

    points = _sheet(seed=2)
    points = points[np.random.default_rng(2).random(len(points)) < 0.5]
    vertices, faces = reconstruct_frame(Frame(points, sensors=np.array([[0.0, 0.0, 5.0]])))
    assert len(faces) > 1000
    assert len(pinched_vertices(faces)) == 0
    assert topology(faces, len(vertices)).nonmanifold_edges == 0
    assert np.abs(vertices[:, 2] - _sheet_height(vertices)).max() < 0.03


def test_outliers_do_not_create_components():
    # Component filtering off: the outlier removal alone must keep stray surface pieces away.
    options = Options(min_component_fraction=0.0)
    for seed in range(3):
        points = _noisy_sphere(seed=seed, count=2500, outliers=0.02)
        vertices, faces = reconstruct_frame(Frame(points), options)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.body_count == 1
        assert np.abs(np.linalg.norm(vertices, axis=1) - 1.0).max() < 0.05


def test_scaling_the_input_scales_the_output():
    points = _noisy_sphere(seed=5, count=2000)
    small_vertices, small_faces = reconstruct_frame(Frame(points))
    large_vertices, large_faces = reconstruct_frame(Frame(points * 10.0))
    assert abs(len(large_faces) - len(small_faces)) <= 0.01 * len(small_faces)
    forward, _ = cKDTree(large_vertices).query(small_vertices * 10.0)
    backward, _ = cKDTree(small_vertices * 10.0).query(large_vertices)
    assert max(forward.max(), backward.max()) < 1e-3 * 10.0


def test_capped_grid_scales_lengths_with_cells():
    # Dense data on a coarse grid: radii follow the cells, not the (much smaller) spacing.
    points = _noisy_sphere(seed=10, count=6000, outliers=0.0, noise=0.002)
    vertices, faces = reconstruct_frame(Frame(points), Options(max_grid=24))
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.body_count == 1
    assert np.abs(np.linalg.norm(vertices, axis=1) - 1.0).max() < 0.06


def test_reconstruct_sequence_keeps_times_and_frames():
    rng = np.random.default_rng(6)
    frames = []
    for i, shift in enumerate([0.0, 0.5]):
        points = _fibonacci_sphere(1500) + rng.normal(scale=NOISE, size=(1500, 3)) + [shift, 0, 0]
        frames.append(Frame(points, time=0.25 * i + 1.0))
    result = reconstruct(PointCloudSequence(frames), Options())
    assert isinstance(result, MeshSequence)
    assert np.allclose(result.times, [1.0, 1.25])
    centres = [vertices.mean(axis=0)[0] for vertices, _ in result.meshes]
    assert centres[0] == pytest.approx(0.0, abs=0.02) and centres[1] == pytest.approx(0.5, abs=0.02)
    assert MIN_FRAMES == 1


def test_registry_and_string_options():
    seq = PointCloudSequence([Frame(_noisy_sphere(seed=7, count=1500, outliers=0.0))])
    result = fourd.reconstruct(seq, method="perframe", smoothing_iterations="2", grid_scale="1.5")
    assert isinstance(result, MeshSequence) and len(result.meshes[0][1]) > 100
    options = method_options("perframe", {"clip_distance": "3", "spacing": "none"})
    assert options.clip_distance == 3.0 and options.spacing is None
    with pytest.raises(InputError, match="valid keys"):
        method_options("perframe", {"nope": "1"})
    with pytest.raises(InputError):
        method_options("perframe", {"grid_scale": "-1"})


def test_options_are_frozen_and_validated():
    options = Options()
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.grid_scale = 2.0  # type: ignore[misc]
    for bad in (
        {"normals_k": 1},
        {"bandwidth": 0.0},
        {"min_component_fraction": 2.0},
        {"max_grid": 12},
        {"orientation": "north"},
    ):
        with pytest.raises(ValueError):
            Options(**bad)


def test_tiny_frame_gives_empty_mesh():
    vertices, faces = reconstruct_frame(Frame(np.random.default_rng(8).normal(size=(10, 3))))
    assert vertices.shape == (0, 3) and faces.shape == (0, 3)


def test_input_normals_are_used():
    points = _fibonacci_sphere(2000)
    inward = Frame(points, normals=-points)
    vertices, faces = reconstruct_frame(inward, Options(use_input_normals=True))
    # Inward normals flip inside and outside: the mesh is wound inwards.
    assert trimesh.Trimesh(vertices, faces, process=False).volume < 0
    vertices, faces = reconstruct_frame(inward, Options(use_input_normals=False))
    assert trimesh.Trimesh(vertices, faces, process=False).volume > 0


def test_taubin_smoothing_reduces_noise_without_shrinking():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    rng = np.random.default_rng(9)
    noisy = sphere.vertices * (1 + rng.normal(scale=0.01, size=(len(sphere.vertices), 1)))
    smoothed = taubin_smooth(noisy, sphere.faces, iterations=10)
    before = np.abs(np.linalg.norm(noisy, axis=1) - 1).mean()
    after = np.abs(np.linalg.norm(smoothed, axis=1) - 1).mean()
    assert after < 0.5 * before
    assert np.linalg.norm(smoothed, axis=1).mean() > 0.98


@pytest.mark.parametrize("mode", ["auto", "sensors"])
def test_normals_face_the_sensor(mode):
    points = _sheet(seed=2)
    for height in (5.0, -5.0):
        normals = oriented_normals(points, sensors=np.array([[0.3, 0.2, height]]), mode=mode)
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
        assert np.mean(np.sign(normals[:, 2]) == np.sign(height)) > 0.99


def test_normals_without_sensors_point_outwards():
    points = _fibonacci_sphere(2000)
    for mode in ("auto", "propagation"):
        normals = oriented_normals(points, mode=mode)
        assert np.mean(np.einsum("ij,ij->i", normals, points) > 0.9) > 0.99


def test_voxel_average():
    points = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.2, 0.1, 0.1], [1.4, 0.1, 0.1]])
    normals = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, 1.0]])
    averaged, averaged_normals = voxel_average(points, 1.0, normals)
    order = np.argsort(averaged[:, 0])
    assert np.allclose(averaged[order], [[0.2, 0.2, 0.2], [1.3, 0.1, 0.1]])
    assert np.allclose(averaged_normals[order][0], [2**-0.5, 2**-0.5, 0])
    assert np.allclose(averaged_normals[order][1], [0, 0, 1])
    alone, none = voxel_average(points, 0.01)
    assert len(alone) == 4 and none is None


def test_cell_corner_minimum_is_the_least_of_the_eight_corners():
    rng = np.random.default_rng(3)
    corner = rng.random((5, 6, 7))
    corner[2, 3, 4] = np.nan
    corner[0, 0, 0] = np.inf
    least = cell_corner_minimum(corner)
    assert least.shape == (4, 5, 6)
    for i, j, k in np.ndindex(least.shape):
        cube = corner[i : i + 2, j : j + 2, k : k + 2]
        expected = np.nan if np.isnan(cube).any() else cube.min()
        assert np.array_equal(least[i, j, k], expected, equal_nan=True)
