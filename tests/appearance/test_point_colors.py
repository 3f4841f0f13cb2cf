"""Colours for points from the calibrated video: they agree with what the scanner itself
recorded, and a surface in front of a point does not lend it its colour."""

import dataclasses

import numpy as np
import pytest

import fourd
from fourd.appearance.cameras import look_at, rays
from fourd.appearance.point_colors import colors_from_video, point_colors, with_video_colors
from fourd.errors import InputError
from fourd.io.video import Video
from fourd.sequence import Frame, PointCloudSequence

RED = np.array([0.9, 0.1, 0.1])


def _back_color(points):
    """The back wall: blue with a gentle green ramp along x."""
    points = np.atleast_2d(points)
    return np.column_stack(
        [np.full(len(points), 0.1), 0.2 + 0.3 * (points[:, 0] + 1) / 2, np.full(len(points), 0.8)]
    )


def _wall(half, z, count):
    g = np.linspace(-half, half, count)
    x, y = np.meshgrid(g, g)
    return np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)


def _render(camera):
    """A red square (|x|, |y| < 0.3 at z = 0.5) in front of the back wall (|x|, |y| < 1, z = 0),
    ray-cast at every pixel centre; black where neither is hit."""
    j, i = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    direction = rays(camera, np.stack([j.ravel(), i.ravel()], axis=1).astype(float))
    origin = camera.center
    image = np.zeros((direction.shape[0], 3))
    hit_back = origin + ((0.0 - origin[2]) / direction[:, 2])[:, None] * direction
    on_back = (np.abs(hit_back[:, :2]) < 1).all(axis=1)
    image[on_back] = _back_color(hit_back[on_back])
    hit_front = origin + ((0.5 - origin[2]) / direction[:, 2])[:, None] * direction
    on_front = (np.abs(hit_front[:, :2]) < 0.3).all(axis=1)
    image[on_front] = RED
    return np.round(image * 255).astype(np.uint8).reshape(camera.height, camera.width, 3)


def _cameras(positions):
    return [
        look_at(f"c{k}", p, [0, 0, 0], [0, 1, 0], focal=70, width=64, height=64)
        for k, p in enumerate(positions)
    ]


#: Cameras in front of the walls: the first looks from the side, so the red square hides a strip
#: of the back wall from it that the others see.
SIDE, FRONT, ABOVE = [2.4, 0.0, 3.0], [-0.5, 0.0, 3.6], [0.0, 1.2, 3.6]


def _hidden_from_the_side(back):
    """Back-wall points the red square hides from the SIDE camera but not (by a margin of about
    three pixels: depth edges widen by the splat and the bilinear sample) from FRONT and ABOVE."""
    def behind(position, half):
        step = (0.5 - back[:, 2]) / (position[2] - back[:, 2])
        at = back + step[:, None] * (np.asarray(position) - back)
        return (np.abs(at[:, :2]) < half).all(axis=1)

    return behind(SIDE, 0.25) & ~behind(FRONT, 0.45) & ~behind(ABOVE, 0.45)


def test_a_point_behind_a_scanned_surface_takes_its_colour_from_the_cameras_that_see_it():
    back = _wall(1.0, 0.0, 120)
    front = _wall(0.3, 0.5, 36)
    points = np.concatenate([back, front])
    cameras = _cameras([SIDE, FRONT])  # two views: no vote, the depth test alone decides
    colors = point_colors(cameras, [_render(c) for c in cameras], points, tolerance=0.15)
    hidden = _hidden_from_the_side(back)
    assert hidden.sum() > 100
    got = colors[: len(back)][hidden]
    assert np.isfinite(got).all()
    assert np.abs(got - _back_color(back[hidden])).max(axis=1).mean() < 0.02
    # the square itself, away from its rim (where every view mixes in the wall behind)
    inner = (np.abs(front[:, :2]) < 0.2).all(axis=1)
    assert np.abs(colors[len(back) :][inner] - RED).max() < 0.03


def test_with_three_views_one_blocked_by_something_not_scanned_is_outvoted():
    back = _wall(1.0, 0.0, 120)  # the red square is filmed but not in the points
    cameras = _cameras([SIDE, FRONT, ABOVE])
    colors = point_colors(cameras, [_render(c) for c in cameras], back, tolerance=0.15)
    hidden = _hidden_from_the_side(back)
    error = np.abs(colors[hidden] - _back_color(back[hidden])).max(axis=1)
    assert np.median(error) < 0.02 and (error > 0.1).mean() < 0.05
    # the same with two views: the blocked camera's red is averaged in
    two = point_colors(cameras[:2], [_render(c) for c in cameras[:2]], back, tolerance=0.15)
    assert np.median(np.abs(two[hidden] - _back_color(back[hidden])).max(axis=1)) > 0.2


def test_the_frontal_view_counts_more_than_the_slanted_one():
    wall = _wall(0.5, 0.0, 60)
    slant = np.radians(70)
    frontal = look_at("f", [0, 0, 3], [0, 0, 0], [0, 1, 0], focal=120, width=96, height=96)
    slanted = look_at(
        "s", [3 * np.sin(slant), 0, 3 * np.cos(slant)], [0, 0, 0], [0, 1, 0], focal=120, width=96, height=96
    )
    images = [np.full((96, 96, 3), 200, np.uint8), np.full((96, 96, 3), 50, np.uint8)]
    normals = np.tile([0.0, 0.0, -1.0], (len(wall), 1))  # the sign does not matter
    weighted = point_colors([frontal, slanted], images, wall, normals=normals, tolerance=0.3)
    plain = point_colors([frontal, slanted], images, wall, tolerance=0.3)
    both = np.abs(plain[:, 0] - 125 / 255) < 1e-9  # both views, both clean
    assert both.mean() > 0.8
    # |cos| 1 against cos 70 degrees at the wall's centre (each point's own ray elsewhere)
    expected = (200 + 50 * np.cos(slant)) / (1 + np.cos(slant)) / 255
    np.testing.assert_allclose(weighted[both, 0], expected, atol=0.03)


@pytest.fixture(scope="module")
def filmed():
    truth = fourd.synth.scene("squash-ball", frames=2)
    return {
        n: fourd.synth.scan(
            truth, resolution=96, appearance="cloth", video=True, video_resolution=n, outliers=0.0
        )
        for n in (96, 64)
    }


def _seen(scans, t):
    from fourd.appearance.anchor_tracks import surface_spacing

    points = scans[t].points
    images = [scans.video.image(c, t) for c in range(len(scans.video.cameras))]
    colors = point_colors(scans.video.cameras, images, points, tolerance=3 * surface_spacing(points))
    return np.isfinite(colors[:, 0])


def test_video_colours_agree_with_the_scanners_own(filmed):
    # both are albedo x shading on the same 0-1 scale (the images 8-bit), noise 0.01 each
    for n, limit in ((96, 0.015), (64, 0.04)):
        scans = filmed[n]
        colors = colors_from_video(scans, 1)
        seen = _seen(scans, 1)
        assert seen.mean() > 0.75
        difference = np.abs(colors - scans[1].colors)
        # measured: 0.010 on the depth cameras' own pixel grid (noise), 0.029 on a coarser one
        # (the cloth's print is finer than its pixels)
        assert np.median(difference[seen]) < limit, n
        assert np.isfinite(colors).all() and colors.min() >= 0 and colors.max() <= 1
        # the unseen take their nearest seen neighbour's: close, not exact
        assert np.median(difference[~seen]) < 3 * limit


def test_a_sequence_without_colours_is_coloured_from_its_video(filmed):
    scans = filmed[96]
    bare = PointCloudSequence(
        (dataclasses.replace(scans[0], colors=None), scans[1]), scans.names, scans.video
    )
    coloured = with_video_colors(bare)
    assert coloured[1] is scans[1]  # frames with colours are kept
    assert np.median(np.abs(coloured[0].colors - scans[0].colors)) < 0.015
    assert with_video_colors(scans) is scans
    assert coloured.video is scans.video


def test_points_no_camera_sees_take_the_nearest_seen_colour():
    cam = look_at("c", [0, 0, 3], [0, 0, 0], [0, 1, 0], focal=30, width=32, height=32)
    inside = _wall(0.5, 0.0, 30)
    outside = np.array([[5.0, 0.0, 0.0]])  # outside the picture
    image = np.full((32, 32, 3), 100, np.uint8)
    frame = Frame(np.concatenate([inside, outside]))
    seq = PointCloudSequence((frame,), video=Video.from_arrays([cam], image[None, None]))
    raw = point_colors([cam], [image], frame.points, tolerance=0.15)
    assert np.isnan(raw[-1]).all() and np.isfinite(raw[:-1]).mean() > 0.5  # the rim is unseen
    np.testing.assert_allclose(colors_from_video(seq, 0), 100 / 255)


def test_bad_inputs_are_refused_in_one_line():
    cam = look_at("c", [0, 0, 3], [0, 0, 0], [0, 1, 0], focal=30, width=32, height=32)
    image = np.full((32, 32, 3), 100, np.uint8)
    wall = _wall(0.5, 0.0, 30)
    plain = PointCloudSequence((Frame(wall),))
    away = PointCloudSequence((Frame(wall + [0, 0, 10]),), video=Video.from_arrays([cam], image[None, None]))
    cases = [
        (lambda: colors_from_video(plain, 0), "no video"),
        (lambda: colors_from_video(away, 3), "outside"),
        (lambda: colors_from_video(away, 0), "no camera of the video sees any point"),
        (lambda: point_colors([cam], [], wall, tolerance=0.1), "one image per camera"),
        (lambda: point_colors([cam], [image], wall, tolerance=0.0), "tolerance"),
        (lambda: point_colors([cam], [image[:16]], wall, tolerance=0.1), "the image is"),
        (lambda: point_colors([cam], [image], wall, normals=wall[:5], tolerance=0.1), "normals"),
    ]
    for call, words in cases:
        with pytest.raises(InputError, match=words) as error:
            call()
        assert "\n" not in str(error.value)
