"""The colour guide: coloured points without video pin down where along the surface the
template's vertices went, and a uniform colour changes little (on crane it costs 10%: see
benchmarks/METHODS.md, ``color_guide``)."""

import numpy as np
import pytest

from fourd import synth
from fourd.appearance.color_guide import PhotometricGuides, colors_of_cleaned
from fourd.methods import kinematic
from fourd.metrics import evaluate


def _run(appearance, guided, scene="squash-ball"):
    truth = synth.scene(scene, frames=6)
    scans = synth.scan(truth, resolution=96, seed=0, appearance=appearance)
    result = kinematic.reconstruct(scans, kinematic.Options(color_guide=guided))
    return evaluate(result, truth, samples=5000, seed=0)


@pytest.fixture(scope="module")
def printed():
    return _run("cloth", False), _run("cloth", True)


def test_printed_colours_cut_the_drift(printed):
    plain, guided = printed
    # measured: mean 0.0235 -> 0.0182, last frame 0.0150 -> 0.0076
    assert guided["correspondence_last"] < 0.7 * plain["correspondence_last"]
    assert guided["correspondence_mean"] < 0.9 * plain["correspondence_mean"]
    assert guided["chamfer"] < 1.15 * plain["chamfer"]


def test_a_uniform_colour_changes_little():
    plain, guided = _run("uniform", False, "bending-arm"), _run("uniform", True, "bending-arm")
    assert guided["correspondence_mean"] <= 1.05 * plain["correspondence_mean"]
    assert guided["correspondence_last"] <= 1.05 * plain["correspondence_last"]


def test_cleaned_points_keep_their_colours_and_frames_without_colour_give_no_guide():
    rng = np.random.default_rng(0)
    raw = rng.random((50, 3))
    colors = rng.random((50, 3))
    assert np.array_equal(colors_of_cleaned(raw, colors, raw[10:20]), colors[10:20])
    assert colors_of_cleaned(raw, None, raw[10:20]) is None
    sphere = rng.normal(size=(400, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    from scipy.spatial import ConvexHull

    faces = ConvexHull(sphere).simplices
    guides = PhotometricGuides(sphere, faces, [0, 1], [sphere, sphere], [sphere, sphere], [None, None],
                               radius=0.3, scale=0.05)
    assert guides[1] is None


@pytest.fixture(scope="module")
def filmed_without_colours():
    """The printed squash ball filmed at 64 pixels, its points stripped of their colours."""
    import dataclasses

    from fourd.sequence import PointCloudSequence

    truth = synth.scene("squash-ball", frames=6)
    scans = synth.scan(truth, resolution=96, seed=0, appearance="cloth", video=True, video_resolution=64)
    bare = PointCloudSequence(
        tuple(dataclasses.replace(f, colors=None) for f in scans.frames), scans.names, scans.video
    )
    return truth, scans, bare


def test_points_without_colours_take_them_from_the_video(filmed_without_colours, monkeypatch):
    truth, _, bare = filmed_without_colours
    guided = evaluate(kinematic.reconstruct(bare), truth, samples=5000, seed=0)

    def refuse(*args, **kwargs):
        raise AssertionError("color_guide=False must do no colour work")

    monkeypatch.setattr("fourd.appearance.point_colors.colors_from_video", refuse)
    plain = evaluate(kinematic.reconstruct(bare, kinematic.Options(color_guide=False)), truth, samples=5000, seed=0)
    # measured: mean 0.0235 -> 0.0187, last 0.0150 -> 0.0057 (the scanner's own colours:
    # 0.0183, 0.0049)
    assert guided["correspondence_last"] < 0.6 * plain["correspondence_last"]
    assert guided["correspondence_mean"] < 0.9 * plain["correspondence_mean"]
    assert guided["chamfer"] < 1.15 * plain["chamfer"]


def test_colours_come_from_one_source_for_every_frame(filmed_without_colours):
    import dataclasses

    from fourd.appearance.color_guide import guide_colors
    from fourd.appearance.point_colors import colors_from_video
    from fourd.sequence import PointCloudSequence

    _, scans, bare = filmed_without_colours
    points = [f.points for f in scans.frames]
    normals = [None] * len(points)
    # every frame coloured: the points' own colours, the video unused
    own = guide_colors(scans, points, normals)
    assert all(np.array_equal(c, f.colors) for c, f in zip(own, scans.frames, strict=True))
    # one frame without: all from the video, so that the frames' colours compare
    mixed = PointCloudSequence((dataclasses.replace(scans[0], colors=None),) + scans.frames[1:], video=scans.video)
    from_video = guide_colors(mixed, points, normals)
    assert np.array_equal(from_video[1], colors_from_video(bare, 1))
    # no colours, no video: no guide
    assert guide_colors(PointCloudSequence(bare.frames), points, normals) is None


def test_a_video_that_sees_none_of_the_points_is_refused_naming_the_way_out(filmed_without_colours):
    from fourd.appearance.color_guide import guide_colors
    from fourd.errors import InputError
    from fourd.sequence import PointCloudSequence

    _, _, bare = filmed_without_colours
    away = [f.points + [0.0, 1000.0, 0.0] for f in bare.frames]  # far above every camera's view
    seq = PointCloudSequence.from_arrays(away)
    seq = PointCloudSequence(seq.frames, video=bare.video)
    with pytest.raises(InputError, match="no camera of the video sees any point.*color_guide=false") as error:
        guide_colors(seq, away, [None] * len(away))
    assert "\n" not in str(error.value)
