import numpy as np
import pytest

from fourd.appearance.cameras import project
from fourd.errors import InputError
from fourd.synth.filming import film_frame, rig_cameras
from fourd.synth.scanner import camera_rays, camera_rig, scan_frame, scan_options
from fourd.synth.scenes import scene


def test_rig_cameras_put_pixel_centres_on_the_scanner_rays():
    rig = camera_rig(np.array([[-1.0, -0.5, -1.0], [1.0, 0.5, 1.0]]), 3)
    cameras = rig_cameras(rig, 24)
    for k, camera in enumerate(cameras):
        origins, directions = camera_rays(rig, k, 24)
        uv, depth = project(camera, origins + 2.0 * directions)
        rows, columns = np.divmod(np.arange(24 * 24), 24)
        np.testing.assert_allclose(uv, np.stack([columns, rows], 1), atol=1e-9)
        assert np.all(depth > 0)
        np.testing.assert_allclose(camera.center, rig.positions[k], atol=1e-12)
        assert camera.name == f"cam_{k}" and (camera.width, camera.height) == (24, 24)


def test_images_show_the_colours_the_scan_records():
    truth = scene("squash-ball", frames=2)
    options = scan_options(None, appearance="cloth", resolution=48, noise=0.0, outliers=0.0, color_noise=0.0)
    rig = camera_rig(truth.bounds(), 3)
    frame = scan_frame(truth, 1, options, rig=rig)
    images = film_frame(truth, 1, options, rig=rig)
    assert images.shape == (3, 48, 48, 3) and images.dtype == np.uint8
    cameras = rig_cameras(rig, 48)
    for k, camera in enumerate(cameras):
        mine = frame.camera == k
        uv, _ = project(camera, frame.clean[mine])
        pixel = np.rint(uv).astype(int)
        seen = images[k, pixel[:, 1], pixel[:, 0]] / 255.0
        np.testing.assert_allclose(seen, frame.colors[mine], atol=0.5 / 255 + 1e-9)
    background = images[:, 0, 0]
    assert np.all(background == background[0])


def test_the_occluder_is_filmed_but_not_scanned():
    truth = scene("squash-ball", frames=3)
    base = dict(appearance="skin", resolution=40, outliers=0.0, color_noise=0.0)
    rig = camera_rig(truth.bounds(), 3)
    plain = film_frame(truth, 1, scan_options(None, **base), rig=rig)
    blocked = film_frame(truth, 1, scan_options(None, occluder=True, **base), rig=rig)
    changed = np.any(plain[0] != blocked[0], axis=2)
    assert changed.sum() > 30


def test_point_truths_and_colourless_scans_cannot_be_filmed():
    from fourd.animation import AnimatedMesh

    points = AnimatedMesh(np.zeros((0, 3)), np.random.default_rng(0).random((2, 50, 3)))
    with pytest.raises(InputError, match="point truth"):
        film_frame(points, 0, scan_options(None, appearance="skin", resolution=16))
    with pytest.raises(InputError, match="appearance"):
        film_frame(scene("squash-ball", frames=1), 0, scan_options(None, resolution=16))
