import numpy as np
import pytest
import trimesh

import fourd
from fourd.animation import AnimatedMesh
from fourd.appearance.anchor_tracks import AnchorOptions, anchors, camera_tracks, merge_tracks
from fourd.errors import InputError


def _grid(n, x0, x1, y0, y1, z):
    x, y = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.full(n * n, z)], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    b, c, d = a + n, a + n + 1, a + 1
    return vertices, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _moving(parts, frames):
    """An AnimatedMesh of ``(vertices, faces, step)`` parts each translated by ``step`` per frame."""
    faces, offset = [], 0
    for vertices, f, _ in parts:
        faces.append(f + offset)
        offset += len(vertices)
    frames_ = [
        np.concatenate([v + t * np.asarray(step, dtype=float) for v, _, step in parts])
        for t in range(frames)
    ]
    return AnimatedMesh(np.concatenate(faces), np.stack(frames_), rest=frames_[0])


#: Two cameras facing the plane z = 0 from either side (the sheet is seen, and coloured, on both).
FACING = dict(cameras=2, first_angle=np.pi / 2, appearance="cloth", video=True, outliers=0.0)


def test_translated_plane_gives_anchors_that_recover_the_translation():
    step = np.array([0.03, -0.02, 0.0])
    truth = _moving([(*_grid(41, -0.5, 0.5, -0.5, 0.5, 0.0), step)], frames=3)
    scans = fourd.synth.scan(truth, resolution=112, **FACING)
    result = anchors(scans)
    assert len(result) == 2
    pixel = 1.2 * truth.diagonal() / 112  # size of a pixel at the plane
    for pair in result:
        assert len(pair.source) > 0.5 * len(scans[pair.first])
        motion = pair.target - pair.source
        np.testing.assert_allclose(np.median(motion, axis=0), step, atol=0.1 * pixel)
        error = np.linalg.norm(motion - step, axis=1)
        assert np.percentile(error, 90) < 0.5 * pixel
        assert (pair.views == 2).mean() > 0.3  # both cameras track many points, and agree
        assert np.all((pair.confidence > 0) & (pair.confidence < 1))
        np.testing.assert_array_equal(pair.source, scans[pair.first].points[pair.index])
    assert result.total == sum(len(p.source) for p in result)


def test_lifted_anchors_lie_on_the_true_surface_within_the_noise():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.8)
    angle = np.deg2rad(4.0)
    turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    rest = np.asarray(sphere.vertices)
    vertices = np.stack([rest @ np.linalg.matrix_power(turn, t).T for t in range(3)])
    truth = AnimatedMesh(sphere.faces, vertices, rest=rest)
    noise = 0.002
    scans = fourd.synth.scan(truth, resolution=112, noise=noise, appearance="cloth", video=True)
    sigma = noise * truth.diagonal()
    pixel = 1.2 * truth.diagonal() / 112
    for pair in anchors(scans):
        off_surface = np.abs(np.linalg.norm(pair.target, axis=1) - 0.8)
        raw = np.abs(np.linalg.norm(scans[pair.second].points, axis=1) - 0.8)
        assert np.percentile(off_surface, 99) < 3 * sigma
        assert np.median(off_surface) < np.median(raw)  # the lift averages the scan noise
        error = np.linalg.norm(pair.target - pair.source @ turn.T, axis=1)
        assert np.median(error) < 0.5 * pixel and np.percentile(error, 90) < pixel


@pytest.fixture(scope="module")
def occluded():
    """A plane (z = 0) and a plate in front of it (z = 0.25) that slides right by about 8
    pixels a frame, seen by one camera: each frame the plate covers a strip of the plane."""
    plane = (*_grid(41, -0.5, 0.5, -0.5, 0.5, 0.0), (0.0, 0.0, 0.0))
    plate = (*_grid(21, -0.55, -0.05, -0.25, 0.25, 0.25), (0.1, 0.0, 0.0))
    truth = _moving([plane, plate], frames=2)
    return fourd.synth.scan(truth, resolution=128, **{**FACING, "cameras": 1})


def _plane_to_plate(seq, index, target):
    source = seq[0].points[index]
    return int(((np.abs(source[:, 2]) < 0.05) & (target[:, 2] > 0.15)).sum())


def test_forward_backward_pruning_removes_anchors_on_a_surface_occluded_in_the_next_frame(occluded):
    unchecked = camera_tracks(occluded, 0, 0, forward_backward=np.inf, photometric=np.inf)
    wrong = _plane_to_plate(occluded, unchecked.index, unchecked.target)
    assert wrong >= 20  # without the check, points the plate covers are tracked onto the plate
    checked = camera_tracks(occluded, 0, 0, photometric=np.inf)
    assert _plane_to_plate(occluded, checked.index, checked.target) <= 0.3 * wrong
    assert len(checked.index) > 0.85 * len(unchecked.index)  # the rest is kept
    assert checked.counts["forward_backward"] < checked.counts["seen"]
    default = anchors(occluded)[0]
    assert _plane_to_plate(occluded, default.index, default.target) <= 2


def test_tracks_of_several_cameras_must_agree():
    index = np.array([0, 0, 1, 1, 2, 2, 2, 3])
    camera = np.array([0, 1, 0, 1, 0, 1, 2, 2])
    target = np.array(
        [[0, 0, 0], [0.01, 0, 0], [0, 0, 0], [1, 0, 0], [5, 5, 5], [5, 5, 5.02], [9, 9, 9], [3, 3, 3]],
        dtype=float,
    )
    reliability = np.full(8, 0.5)
    kept, merged, confidence, views, agreed = merge_tracks(index, camera, target, reliability, 3, 0.05)
    assert kept.tolist() == [0, 2, 3]  # point 1's two cameras disagree: dropped
    np.testing.assert_allclose(merged, [[0.005, 0, 0], [5, 5, 5.01], [3, 3, 3]])
    assert views.tolist() == [2, 2, 1] and agreed == 5  # point 2's third camera is out
    np.testing.assert_allclose(confidence, [0.75, 0.75, 0.5])


def test_options_filter_and_thin():
    truth = _moving([(*_grid(31, -0.5, 0.5, -0.5, 0.5, 0.0), (0.02, 0.0, 0.0))], frames=2)
    scans = fourd.synth.scan(truth, resolution=80, **FACING)
    everything = anchors(scans)[0]
    both = anchors(scans, min_cameras=2)[0]
    thinned = anchors(scans, AnchorOptions(thin=4.0))[0]
    count = len(everything.source)
    assert 0 < len(both.source) < count and np.all(both.views >= 2)
    assert 0 < len(thinned.source) < 0.25 * count
    assert everything.counts["anchors"] == len(everything.source)


def test_anchors_need_video_and_good_options():
    truth = _moving([(*_grid(11, -0.5, 0.5, -0.5, 0.5, 0.0), (0.02, 0.0, 0.0))], frames=2)
    plain = fourd.synth.scan(truth, resolution=32, cameras=2, first_angle=np.pi / 2)
    with pytest.raises(InputError, match="video"):
        fourd.appearance.anchors(plain)
    with pytest.raises(InputError, match="unknown anchor option"):
        anchors(plain, nope=1)
    with pytest.raises(InputError, match="forward_backward"):
        AnchorOptions(forward_backward=0)
    with pytest.raises(InputError, match="min_cameras"):
        AnchorOptions(min_cameras=0)
