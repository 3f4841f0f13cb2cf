"""The wrinkling step (thesis 4.5): rotations blended over space and time, vertices positioned
by them, and folds seen in a video put into a garment that lacks them."""

import numpy as np
import pytest

from fourd.animation import AnimatedMesh
from fourd.geometry.low_pass import low_pass_surface
from fourd.geometry.meshes import face_adjacency
from fourd.methods.garment import (
    FrameAnchors,
    WrinkleOptions,
    hold_to_data,
    position_vertices,
    spacetime_rotations,
    wrinkle,
)
from fourd.metrics.folds import fold_heights, fold_recall


def _grid(n=21):
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + 1], 1), np.stack([a + 1, a + n, a + n + 1], 1)])
    return vertices, faces


def test_an_anchor_rotation_holds_at_the_anchor_and_fades_over_space_and_time():
    vertices, faces = _grid()
    centres = vertices[faces].mean(axis=1)
    anchor = int(np.argmin(np.linalg.norm(centres[:, :2] - 0.5, axis=1)))
    target = np.array([[0.0, 0.5, 0.0]])
    none = FrameAnchors(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), 0, 0, ())
    anchors = [none, FrameAnchors(np.array([anchor]), target, 1, 1, (0,)), none]
    rotations = spacetime_rotations(faces, 3, anchors)
    assert np.allclose(spacetime_rotations(faces, 3, [none] * 3), 0.0)
    at = rotations[1, anchor]
    assert np.linalg.norm(at - target[0]) < 0.25 * 0.5  # a lone anchor among its neighbours
    assert np.allclose(at / np.linalg.norm(at), [0, 1, 0])
    distance = np.linalg.norm(centres - centres[anchor], axis=1)
    near, far = distance < 0.1, distance > 0.4
    size = np.linalg.norm(rotations[1], axis=1)
    assert size[near].mean() > 5 * size[far].mean()
    assert 0 < np.linalg.norm(rotations[0, anchor]) < np.linalg.norm(at)  # the neighbouring frames too, less
    assert np.allclose(rotations[0], rotations[2])
    pairs, _ = face_adjacency(faces)
    assert np.abs(rotations[1, pairs[:, 0]] - rotations[1, pairs[:, 1]]).max() < 0.25  # smooth


def test_positioning_keeps_a_mesh_without_rotations_and_turns_one_turned_everywhere():
    vertices, faces = _grid()
    vertices[:, 2] = 0.1 * np.sin(3 * vertices[:, 0])
    assert np.allclose(position_vertices(vertices, faces, np.zeros((len(faces), 3))), vertices)
    turn = np.array([0.2, -0.1, 0.3])
    from scipy.spatial.transform import Rotation

    rotated = position_vertices(vertices, faces, np.tile(turn, (len(faces), 1)), pull=1e-8)
    expected = Rotation.from_rotvec(turn).apply(vertices)
    assert np.allclose(rotated - rotated.mean(axis=0), expected - expected.mean(axis=0), atol=1e-5)


def test_wrinkles_move_an_observed_vertex_only_toward_its_data_and_a_completed_one_freely():
    vertices, _ = _grid()
    data = vertices.copy()  # the scan: the plane z = 0
    normals = np.tile([0.0, 0.0, 1.0], (len(data), 1))
    rng = np.random.default_rng(3)
    before = vertices + np.c_[np.zeros((len(vertices), 2)), rng.uniform(-0.02, 0.02, len(vertices))]
    after = before + np.c_[rng.uniform(-0.01, 0.01, (len(vertices), 2)), rng.uniform(-0.05, 0.05, len(vertices))]
    free = np.zeros(len(vertices), dtype=bool)
    free[:40] = True
    held = hold_to_data(before, after, data, normals, free)
    assert np.array_equal(held[free], after[free])
    assert np.allclose(held[~free, :2], before[~free, :2])  # no move along the data's surface
    assert np.all(np.abs(held[~free, 2]) <= np.abs(before[~free, 2]) + 1e-12)  # never off the data
    toward = ~free & (before[:, 2] * (after[:, 2] - before[:, 2]) < 0)
    assert toward.sum() > 100
    expected = np.where(np.abs(after[:, 2]) < np.abs(before[:, 2]), after[:, 2], 0.0)  # crossing: onto it
    expected = np.where(np.sign(after[:, 2]) == np.sign(before[:, 2]), expected, 0.0)
    assert np.allclose(held[toward, 2], expected[toward])
    assert np.allclose(held[~free & ~toward, 2], before[~free & ~toward, 2])


@pytest.fixture(scope="module")
def filmed_tshirt():
    """Three frames of the T-shirt with folds, filmed under diffuse light, and the same frames
    with their folds smoothed away (what a capture that misses shallow folds gives)."""
    from fourd import synth

    truth = synth.scene("tshirt", frames=20)
    frames = AnimatedMesh(truth.faces, truth.vertices[3:6])
    scans = synth.scan(frames, resolution=32, appearance="uniform", video=True, video_resolution=384,
                       lighting="diffuse")
    diagonal = frames.diagonal()
    smooth = np.stack([low_pass_surface(v, frames.faces, 0.1 * diagonal) for v in frames.vertices])
    return frames, smooth, scans.video


def test_folds_seen_in_the_video_come_back_into_a_garment_smoothed_flat(filmed_tshirt):
    truth, smooth, video = filmed_tshirt
    diagonal = truth.diagonal()
    result = wrinkle(smooth, truth.faces, video, WrinkleOptions())
    assert sum(frame.used for frame in result.anchors) >= 10
    before = fold_recall(AnimatedMesh(truth.faces, smooth), truth)
    after = fold_recall(AnimatedMesh(truth.faces, result.vertices), truth)
    assert after["fold_recall"] > before["fold_recall"] + 0.1
    assert after["fold_precision"] > 0.7  # the folds made are where the truth has folds
    for t in range(len(smooth)):
        made = result.vertices[t] - smooth[t]
        heights = fold_heights(truth.vertices[t], truth.faces, 0.1 * diagonal)
        moved = np.linalg.norm(made, axis=1)
        # the garment moves where the truth folds, and stays away from them
        assert moved[np.abs(heights) > 0.004 * diagonal].mean() > 1.5 * moved[np.abs(heights) < 0.001 * diagonal].mean()
    # nothing drifts: every vertex stays within the folds' depth of where it was
    assert np.linalg.norm(result.vertices - smooth, axis=2).max() < 0.03 * diagonal
