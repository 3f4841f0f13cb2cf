"""Metrics against analytic truths built from small trimesh primitives."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from fourd import AnimatedMesh, InputError, MeshSequence
from fourd.metrics import (
    enclosed_volume,
    evaluate,
    evaluate_files,
    format_report,
    load_truth,
    metric_floor,
    topology,
)

SAMPLES = 6000


def moving_sphere(frames: int = 6, *, subdivisions: int = 3) -> AnimatedMesh:
    """A unit sphere that travels along x and squashes along y (volume not preserved),
    accelerating (so its trajectories have non-zero second differences)."""
    sphere = trimesh.creation.icosphere(subdivisions)
    t = np.linspace(0.0, 1.0, frames) ** 2
    vertices = np.stack([sphere.vertices * [1.0, 1.0 - 0.3 * s, 1.0] + [1.5 * s, 0.0, 0.0] for s in t])
    return AnimatedMesh(sphere.faces, vertices)


def translating_sphere(frames: int = 6) -> AnimatedMesh:
    """A sphere accelerating along x (a rigid motion)."""
    sphere = trimesh.creation.icosphere(3)
    return AnimatedMesh(sphere.faces, np.stack([sphere.vertices + [0.1 * t**2, 0.0, 0.0] for t in range(frames)]))


def waving_plane(frames: int = 5, *, n: int = 40) -> AnimatedMesh:
    """An open square sheet (2 x 2) in the xy plane, rising slowly along z."""
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing="ij")
    flat = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    vertices = np.stack([flat + [0.0, 0.0, 0.05 * t] for t in range(frames)])
    return AnimatedMesh(faces, vertices)


def test_truth_scores_at_the_floor():
    truth = moving_sphere()
    floor = metric_floor(truth, samples=SAMPLES, seed=1)
    report = evaluate(truth, truth, samples=SAMPLES, seed=1)
    # The floor is the truth against itself with independent samples: non-zero but small.
    assert 0 < floor["chamfer"] < 0.01
    assert report["chamfer"] <= floor["chamfer"] * 1.001
    assert report["correspondence_mean"] < 1e-9
    assert floor["correspondence_last"] < 1e-9
    assert abs(report["jitter"] - 1.0) < 1e-6
    # A different sampling seed gives a floor of the same size.
    other = metric_floor(truth, samples=SAMPLES, seed=7)
    assert abs(other["chamfer"] - floor["chamfer"]) < 0.25 * floor["chamfer"]


def test_denser_sampling_lowers_the_floor():
    truth = moving_sphere(frames=3)
    coarse = metric_floor(truth, samples=2000)["chamfer"]
    dense = metric_floor(truth, samples=20000)["chamfer"]
    assert dense < 0.5 * coarse


def test_frame_zero_held_still_scores_badly_on_a_moving_truth():
    truth = moving_sphere()
    still = AnimatedMesh(truth.faces, np.repeat(truth.vertices[:1], truth.frame_count, axis=0))
    report = evaluate(still, truth, samples=SAMPLES)
    floor = metric_floor(truth, samples=SAMPLES)
    assert report["correspondence_first"] < 1e-9
    # The sphere's centre moved 1.5 units; the diagonal is about 3.9 units.
    assert report["correspondence_last"] > 0.3
    assert report["chamfer"] > 10 * floor["chamfer"]
    curve = report["per_frame"]["correspondence"]
    assert len(curve) == truth.frame_count and np.all(np.diff(curve) > 0)
    assert report["jitter"] < 1e-6  # a still output does not move at all


def test_rigid_shift_scores_the_known_shift():
    truth = translating_sphere()
    shift = np.array([0.0, 0.0, 0.08])
    moved = AnimatedMesh(truth.faces, truth.vertices + shift)
    report = evaluate(moved, truth, samples=SAMPLES)
    # Binding to the nearest surface point at frame 0 projects the shift onto the normal: the
    # error is each vertex's distance to the true surface (checked against trimesh), and a rigid
    # translation keeps it in every frame.
    mesh = trimesh.Trimesh(truth.vertices[0], truth.faces, process=False)
    _, distance, _ = trimesh.proximity.closest_point(mesh, moved.vertices[0])
    expected = distance.mean() / truth.diagonal()
    for key in ("correspondence_mean", "correspondence_first", "correspondence_last"):
        assert abs(report[key] - expected) < 0.02 * expected
    assert report["correspondence_last"] < np.linalg.norm(shift) / truth.diagonal()
    assert abs(report["jitter"] - 1.0) < 0.02
    assert report["volume_change"] < 1e-9 and report["truth_volume_change"] < 1e-9


def test_shift_along_the_normal_of_a_sheet_is_the_accuracy():
    truth = waving_plane()
    shift = 0.04
    moved = AnimatedMesh(truth.faces, truth.vertices + [0.0, 0.0, shift])
    report = evaluate(moved, truth, samples=SAMPLES)
    floor = metric_floor(truth, samples=SAMPLES)
    expected = shift / truth.diagonal()
    # Binding is to the nearest surface point: exactly the normal shift on a plane.
    assert abs(report["correspondence_mean"] - expected) < 0.02 * expected
    # Sample-to-sample distances add the in-plane sampling gap (the floor) in quadrature at most.
    assert expected * 0.98 < report["accuracy"] < np.hypot(expected, 2 * floor["accuracy"]) * 1.02
    assert expected * 0.98 < report["completeness"] < np.hypot(expected, 2 * floor["completeness"]) * 1.02


def test_a_mesh_sequence_has_no_correspondence_but_surface_metrics():
    truth = moving_sphere(frames=4)
    sequence = MeshSequence(tuple(truth.frame(t) for t in range(truth.frame_count)))
    report = evaluate(sequence, truth, samples=SAMPLES)
    assert report["result_kind"] == "MeshSequence"
    assert report["correspondence_mean"] is None and report["jitter"] is None
    assert report["chamfer"] < 0.01
    json.dumps(report)  # JSON-ready


def test_observed_split_separates_filled_regions():
    truth = waving_plane(frames=3)
    observed = np.ones((3, truth.vertex_count), dtype=bool)
    observed[:, truth.vertices[0, :, 0] > 0] = False  # the half sheet with x > 0 was filled in
    vertices = truth.vertices.copy()
    vertices[:, truth.vertices[0, :, 0] > 0, 2] += 0.1  # ... and is wrong by 0.1 along z
    result = AnimatedMesh(truth.faces, vertices, observed=observed)
    report = evaluate(result, truth, samples=SAMPLES)
    assert 0.35 < report["filled_fraction"] < 0.65
    assert report["completeness_filled"] > 5 * report["completeness_observed"]


def test_frame_count_mismatch_is_an_input_error():
    truth = moving_sphere(frames=4)
    with pytest.raises(InputError, match="frames"):
        evaluate(truth.select(0, 3), truth, samples=100)


def test_point_truth_uses_its_points():
    truth = moving_sphere(frames=3)
    points = AnimatedMesh(np.zeros((0, 3), dtype=np.int64), truth.vertices)
    floor = metric_floor(points, samples=SAMPLES)
    assert floor["correspondence_mean"] < 1e-12
    assert floor["closed_manifold"] is None and floor["volume_change"] is None
    report = evaluate(truth, points, samples=SAMPLES)
    # Vertices of the mesh are the truth points: exact correspondence, small surface distances.
    assert report["correspondence_mean"] < 1e-12
    assert report["chamfer"] < 0.02


def test_topology_of_known_meshes():
    sphere = topology(trimesh.creation.icosphere(2).faces)
    assert sphere.components == 1 and sphere.boundary_loops == 0 and sphere.euler == 2
    assert sphere.closed_manifold and sphere.oriented and sphere.nonmanifold_edges == 0
    sheet = topology(waving_plane(frames=1, n=6).faces)
    assert sheet.components == 1 and sheet.boundary_loops == 1 and sheet.euler == 1
    assert not sheet.closed_manifold
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    torus_topology = topology(torus.faces)
    assert torus_topology.euler == 0 and torus_topology.closed_manifold
    two = trimesh.util.concatenate([trimesh.creation.icosphere(1), trimesh.creation.box().apply_translation([3, 0, 0])])
    assert topology(two.faces).components == 2
    # Three triangles sharing one edge: one non-manifold edge.
    fan = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert topology(fan).nonmanifold_edges == 1


def test_volume_of_a_sphere_and_rigid_motion():
    sphere = trimesh.creation.icosphere(4)
    assert abs(enclosed_volume(sphere.vertices, sphere.faces) - 4 / 3 * np.pi) < 0.01 * 4 / 3 * np.pi
    rotation = trimesh.transformations.rotation_matrix(0.7, [1, 2, 3])[:3, :3]
    frames = np.stack([sphere.vertices @ np.linalg.matrix_power(rotation, t).T + [0.3 * t, 0, 0] for t in range(4)])
    rigid = AnimatedMesh(sphere.faces, frames)
    report = evaluate(rigid, rigid, samples=2000)
    assert report["volume_change"] < 1e-9
    assert report["closed_manifold"] == 1.0
    squashed = evaluate(moving_sphere(frames=4), moving_sphere(frames=4), samples=2000)
    assert squashed["volume_change"] > 0.25  # the y axis shrinks to 0.7


def test_files_and_report(tmp_path):
    truth = moving_sphere(frames=3, subdivisions=2)
    result_path = tmp_path / "result.npz"
    truth_path = tmp_path / "truth.npz"
    for path, mesh in ((result_path, truth), (truth_path, truth)):
        np.savez(path, vertices=mesh.vertices.astype(np.float32), faces=mesh.faces.astype(np.int32),
                 times=mesh.times, observed=mesh.observed)
    report = evaluate_files(result_path, truth_path, samples=3000)
    assert report["correspondence_mean"] < 1e-6
    assert report["floor"]["chamfer"] > 0
    text = format_report(report)
    assert "Chamfer" in text and "floor" in text
    points_path = tmp_path / "points.npz"
    np.savez(points_path, points=truth.vertices.astype(np.float16), loc=np.array([1.0, 0, 0]), scale=np.array(2.0))
    points = load_truth(points_path)
    assert len(points.faces) == 0
    assert np.allclose(points.vertices, truth.vertices.astype(np.float16) * 2.0 + [1.0, 0, 0])
    with pytest.raises(InputError):
        evaluate_files(tmp_path / "missing.npz", truth_path)


@pytest.mark.slow
def test_crane_floor_matches_the_baselines_protocol():
    from fourd import synth
    from fourd.synth.data import shared_data_dir

    if shared_data_dir() is None or not (shared_data_dir() / "crane.npz").exists():
        pytest.skip("the shared data (../shared/data/crane.npz) is not there")
    truth = synth.scene("crane")
    floor = metric_floor(truth)
    # BASELINES.md: Chamfer floor 0.0013 on crane with 60,000 samples per surface.
    assert 0.0010 < floor["chamfer"] < 0.0016
    assert floor["correspondence_mean"] < 1e-9 and floor["closed_manifold"] == 1.0
