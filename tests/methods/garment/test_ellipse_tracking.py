"""Garment boundary ellipses (thesis Appendix B): fitting, RANSAC with pruning, tracking and
the off-surface anchors."""

import numpy as np
import pytest

from fourd.errors import InputError
from fourd.methods.garment import (
    TrackingOptions,
    fit_ellipse,
    initial_ellipses,
    loop_ellipse,
    track_boundary,
)


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _ellipse_points(center, rotation, a, b, angles):
    local = np.column_stack([a * np.cos(angles), b * np.sin(angles), np.zeros(len(angles))])
    return center + local @ rotation.T


def _tube(radius=1.0, length=2.0, rings=12, around=40):
    """An open cylinder along z: two boundary loops, at z = 0 and z = length."""
    t = np.linspace(0, 2 * np.pi, around, endpoint=False)
    z = np.linspace(0, length, rings)
    vertices = np.array([[radius * np.cos(a), radius * np.sin(a), h] for h in z for a in t])
    faces = []
    for r in range(rings - 1):
        for i in range(around):
            a, b = r * around + i, r * around + (i + 1) % around
            c, d = a + around, b + around
            faces += [[a, b, d], [a, d, c]]
    return vertices, np.array(faces)


def test_ellipse_recovered_from_half_a_noisy_boundary():
    rng = np.random.default_rng(3)
    rotation = _rotation([1, 2, 0.5], 0.7)
    center = np.array([0.3, -0.2, 1.0])
    half = _ellipse_points(center, rotation, 2.0, 1.2, rng.uniform(0, np.pi, 80))
    ellipse = fit_ellipse(half + rng.normal(0, 0.005, half.shape))
    assert np.linalg.norm(ellipse.center - center) < 0.03
    assert np.allclose(ellipse.radii, [2.0, 1.2], atol=0.03)
    assert abs(abs(ellipse.normal @ rotation[:, 2]) - 1) < 1e-3


def test_an_opening_merged_with_an_occlusion_hole_keeps_its_own_ellipse():
    # a sleeve's hem seen over 60% of it, the rest of its boundary loop running down into the
    # sleeve around a hole the cameras missed: one loop, two shapes
    rng = np.random.default_rng(5)
    rotation = _rotation([0.3, 1, 0.2], 0.5)
    center = np.array([0.2, 0.1, -0.4])
    hem = _ellipse_points(center, rotation, 1.0, 0.7, np.linspace(0.0, 1.2 * np.pi, 70))
    start, end = hem[-1], hem[0]
    s = np.linspace(0, 1, 60)[1:-1, None]
    depth = np.sin(np.pi * s) * 0.9 * rotation[:, 2]  # away from the hem's plane
    hole = start + s * (end - start) - depth + 0.25 * np.sin(2 * np.pi * s) * rotation[:, 0]
    loop = np.concatenate([hem, hole]) + rng.normal(0, 0.004, (len(hem) + len(hole), 3))
    ellipse = loop_ellipse(loop)
    assert np.linalg.norm(ellipse.center - center) < 0.03
    assert np.allclose(ellipse.radii, [1.0, 0.7], atol=0.03)
    assert abs(abs(ellipse.normal @ rotation[:, 2]) - 1) < 1e-2
    # the least-squares ellipse of the whole loop lies between the two
    assert np.linalg.norm(fit_ellipse(loop).center - center) > 0.1


def test_points_on_a_line_have_no_ellipse():
    line = np.outer(np.linspace(0, 1, 10), [1.0, 2.0, 0.0])
    with pytest.raises(InputError):
        fit_ellipse(line)


def test_tracking_keeps_the_garment_boundary_where_half_is_missing_and_holes_lie_beside():
    """Each frame sees only half of the moving boundary (the other half occluded) and the
    boundary of a hole nearby: the tracked centre stays on the true boundary's centre."""
    rng = np.random.default_rng(0)
    rotation = _rotation([0, 1, 0], 0.3)
    frames, truth = [], []
    for t in range(8):
        center = np.array([0.08 * t, 0.02 * t, 0.0])
        seen = rng.uniform(0, np.pi, 60) + 0.2 * t  # a different half each frame
        boundary = _ellipse_points(center, rotation, 1.0, 0.7, seen)
        hole = _ellipse_points(center + [0.9, 0.4, 0.3], rotation, 0.25, 0.2, rng.uniform(0, 2 * np.pi, 30))
        frames.append(np.concatenate([boundary, hole]) + rng.normal(0, 0.003, (90, 3)))
        truth.append(center)
    first = fit_ellipse(_ellipse_points(truth[0], rotation, 1.0, 0.7, np.linspace(0, 2 * np.pi, 50)))
    track = track_boundary(frames, first, TrackingOptions(time_sigma=0))
    assert track.found.all()
    assert np.linalg.norm(track.centers - np.array(truth), axis=1).max() < 0.03
    assert np.allclose(track.radii, [1.0, 0.7], atol=0.03)


def test_anchor_follows_a_translating_boundary_and_skipped_frames_are_interpolated():
    vertices, faces = _tube()
    first = initial_ellipses(vertices, faces, 2)
    assert np.allclose([abs(e.normal[2]) for e in first], 1.0, atol=1e-6)
    # the tube lies behind each opening: the normals point away from it
    assert sorted(np.sign([e.normal[2] for e in first]).tolist()) == [-1.0, 1.0]
    top = max(first, key=lambda e: e.center[2])
    ring = vertices[np.isclose(vertices[:, 2], top.center[2])]
    shifts = np.array([[0.1 * t, 0.05 * t, 0.0] for t in range(6)])
    frames = [ring + s for s in shifts]
    frames[3] = np.zeros((0, 3))  # the boundary not seen at all in frame 3
    track = track_boundary(frames, top, TrackingOptions(time_sigma=0, anchor_offset=0.5))
    assert track.found.tolist() == [True, True, True, False, True, True]
    expected = top.center + shifts + 0.5 * np.array([0, 0, 1.0])  # mean radius 1, normal +z
    assert np.linalg.norm(track.anchors - expected, axis=1).max() < 1e-3


def test_smoothing_in_time_reduces_jitter():
    rng = np.random.default_rng(1)
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    jitter = rng.normal(0, 0.02, (12, 3))
    frames = [_ellipse_points(j, np.eye(3), 1.0, 0.8, angles) for j in jitter]
    first = fit_ellipse(frames[0])
    rough = track_boundary(frames, first, TrackingOptions(time_sigma=0))
    smooth = track_boundary(frames, first, TrackingOptions(time_sigma=2.0))
    assert np.allclose(rough.centers, jitter, atol=1e-6)
    assert np.std(np.diff(smooth.centers, axis=0)) < 0.5 * np.std(np.diff(rough.centers, axis=0))


def test_the_smoothing_chosen_by_leave_one_out_follows_a_swing_and_averages_jitter_out():
    """``time_sigma`` None: a boundary swinging in an arc (found exactly in every frame) is
    smoothed least, so its centres stay on the arc; one standing still but found with jitter
    is smoothed most, as steadily as a fixed width of 2 frames; a take of 4 frames is smoothed
    1 frame wide."""
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    swing = 0.6 * np.sin(np.linspace(0, 2 * np.pi, 20))  # radians: there and back
    arc = np.column_stack([3 * np.sin(swing), 3 * (1 - np.cos(swing)), np.zeros(20)])
    frames = [_ellipse_points(c, _rotation([0, 0, 1], a), 1.0, 0.8, angles) for c, a in zip(arc, swing, strict=True)]
    chosen = track_boundary(frames, fit_ellipse(frames[0]), TrackingOptions())
    fixed = track_boundary(frames, fit_ellipse(frames[0]), TrackingOptions(time_sigma=1.0))
    lag, fixed_lag = (np.linalg.norm(t.centers - arc, axis=1).max() for t in (chosen, fixed))
    assert lag < 0.5 * fixed_lag and fixed_lag > 0.05
    jitter = np.random.default_rng(1).normal(0, 0.02, (20, 3))
    frames = [_ellipse_points(j, np.eye(3), 1.0, 0.8, angles) for j in jitter]
    chosen = track_boundary(frames, fit_ellipse(frames[0]), TrackingOptions())
    widest = track_boundary(frames, fit_ellipse(frames[0]), TrackingOptions(time_sigma=2.0))
    assert np.allclose(chosen.centers, widest.centers)
    short = frames[:4]  # too few frames to choose: 1 frame wide
    chosen = track_boundary(short, fit_ellipse(short[0]), TrackingOptions())
    one = track_boundary(short, fit_ellipse(short[0]), TrackingOptions(time_sigma=1.0))
    assert np.allclose(chosen.centers, one.centers)


def test_too_few_boundary_loops_is_an_input_error():
    vertices, faces = _tube()
    with pytest.raises(InputError, match="boundary loops"):
        initial_ellipses(vertices, faces, 3)


def test_the_tshirts_four_boundaries_are_tracked_within_two_percent_of_the_diagonal():
    """On the T-shirt truth, each frame showing only part of each boundary (a third of every
    loop hidden, as the underarms are), the tracked centres stay within 2% of the diagonal of
    the true loops' centres."""
    from fourd.geometry.boundary_loops import boundary_loops
    from fourd.synth.scenes import scene

    truth = scene("tshirt", frames=20)
    loops = boundary_loops(truth.faces, truth.vertex_count)
    first = initial_ellipses(truth.vertices[0], truth.faces, 4)
    rng = np.random.default_rng(2)
    seen = []
    for t in range(truth.frame_count):
        parts = []
        for loop in loops:
            start = rng.integers(len(loop))
            hidden = (np.arange(len(loop)) - start) % len(loop) < len(loop) // 3
            parts.append(truth.vertices[t, loop[~hidden]])
        seen.append(np.concatenate(parts))
    diagonal = truth.diagonal()
    for ellipse in first:
        loop = min(loops, key=lambda l: np.linalg.norm(truth.vertices[0, l].mean(axis=0) - ellipse.center))
        track = track_boundary(seen, ellipse, TrackingOptions(time_sigma=0))
        true_centres = truth.vertices[:, loop].mean(axis=1)
        assert np.linalg.norm(track.centers - true_centres, axis=1).max() < 0.02 * diagonal


def test_a_keyframe_carries_the_track_over_frames_the_search_cannot_follow(tmp_path):
    import json

    from fourd.methods.garment import read_keyframes

    vertices, faces = _tube()
    top = max(initial_ellipses(vertices, faces, 2), key=lambda e: e.center[2])
    ring = vertices[np.isclose(vertices[:, 2], top.center[2])]
    # the boundary jumps by three radii at frame 3 (too far for the search) and stays there
    shifts = np.array([[0.0, 0.0, 0.0]] * 3 + [[3.0, 0.0, 0.0]] * 3)
    frames = [ring + s for s in shifts]
    lost = track_boundary(frames, top, TrackingOptions(time_sigma=0))
    assert lost.found.tolist() == [True, True, True, False, False, False]
    picked = ring[::5] + shifts[3]  # eight points a user clicked on the boundary in frame 3
    path = tmp_path / "keyframes.json"
    path.write_text(json.dumps({"keyframes": [{"frame": 3, "points": picked.tolist()}]}))
    keyframes = read_keyframes(path)
    kept = track_boundary(frames, top, TrackingOptions(time_sigma=0, reach=4.0), keyframes)
    assert kept.found.tolist() == [True] * 6
    assert np.linalg.norm(kept.centers - (top.center + shifts), axis=1).max() < 1e-6


@pytest.mark.parametrize("content, message", [
    ("not json", "not a readable JSON"),
    ('{"keyframes": [{"frame": 1}]}', 'needs "frame" and "points"'),
    ('{"keyframes": [{"frame": -1, "points": []}]}', "integer >= 0"),
    ('{"keyframes": [{"frame": 1, "points": [[0, 0, 0], [1, 1, 1]]}]}', "at least six"),
    ('{"keyframes": [{"frame": 1, "points": [[0,0,0],[1,0,0],[2,0,0],[3,0,0],[4,0,0],[5,0,0]]}]}', "no ellipse"),
])
def test_a_bad_keyframes_file_names_the_file_and_the_entry(tmp_path, content, message):
    from fourd.methods.garment import read_keyframes

    path = tmp_path / "keys.json"
    path.write_text(content)
    with pytest.raises(InputError, match=message) as error:
        read_keyframes(path)
    assert "keys.json" in str(error.value)
