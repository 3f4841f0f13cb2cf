import json

import numpy as np
import pytest

from fourd.appearance.cameras import (
    Camera,
    in_image,
    look_at,
    project,
    rays,
    read_cameras,
    unproject,
    write_cameras,
)
from fourd.errors import InputError


def _camera():
    return look_at("cam", [1.0, 2.0, 4.0], [0.0, 0.0, 0.0], [0, 1, 0], focal=80, width=64, height=48)


def test_project_follows_the_opencv_convention():
    cam = Camera("c", [[100, 0, 20], [0, 100, 10], [0, 0, 1]], np.eye(3), [0, 0, 5], 40, 20)
    uv, depth = project(cam, [[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0], [0, 0, -6]])
    np.testing.assert_allclose(uv[:3], [[20, 10], [30, 10], [20, 20]])  # x right, y down
    np.testing.assert_allclose(depth, [5, 5, 5, -1])
    assert np.isnan(uv[3]).all()  # behind the camera
    np.testing.assert_allclose(cam.center, [0, 0, -5])
    np.testing.assert_allclose(cam.forward, [0, 0, 1])


def test_unproject_inverts_project_and_rays_point_at_the_points():
    cam = _camera()
    points = np.random.default_rng(0).uniform(-0.5, 0.5, (50, 3))
    uv, depth = project(cam, points)
    np.testing.assert_allclose(unproject(cam, uv, depth), points, atol=1e-12)
    direction = points - cam.center
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    np.testing.assert_allclose(rays(cam, uv), direction, atol=1e-12)


def test_look_at_puts_the_target_at_the_principal_point_with_up_at_the_top():
    cam = _camera()
    uv, _ = project(cam, [[0.0, 0.0, 0.0], [0.0, 0.3, 0.0]])
    np.testing.assert_allclose(uv[0], [31.5, 23.5], atol=1e-12)
    assert uv[1, 1] < uv[0, 1]  # world up is image up (smaller v)
    assert in_image(cam, [[-0.5, -0.5], [63.49, 47.49], [-0.51, 0], [64, 10]]).tolist() == [
        True,
        True,
        False,
        False,
    ]


def test_cameras_json_round_trip(tmp_path):
    cams = (_camera(), look_at("b", [0, 0, 3], [0, 0, 0], [0, 1, 0], focal=50, width=32, height=32))
    write_cameras(tmp_path / "cameras.json", cams)
    data = json.loads((tmp_path / "cameras.json").read_text())
    assert sorted(data["cameras"][0]) == ["K", "R", "height", "name", "t", "width"]
    back = read_cameras(tmp_path / "cameras.json")
    assert [c.name for c in back] == ["cam", "b"]
    for a, b in zip(cams, back, strict=True):
        np.testing.assert_allclose(a.K, b.K)
        np.testing.assert_allclose(a.R, b.R)
        np.testing.assert_allclose(a.t, b.t)
        assert (a.width, a.height) == (b.width, b.height)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"K": [[0, 0, 1], [0, 1, 1], [0, 0, 1]]}, "fx, fy > 0"),
        ({"R": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, "not a rotation"),
        ({"t": [0, 0]}, "t must have shape"),
        ({"width": 0}, "width must be a positive integer"),
        ({"name": "a/b"}, "cannot name a folder"),
        ({"K": "x"}, "K is not numeric"),
    ],
)
def test_bad_camera_entries_name_the_file(tmp_path, change, message):
    entry = {"name": "c", "K": np.eye(3).tolist(), "R": np.eye(3).tolist(), "t": [0, 0, 1], "width": 4, "height": 4}
    entry.update(change)
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"cameras": [entry]}))
    with pytest.raises(InputError, match=message) as info:
        read_cameras(path)
    assert str(path) in str(info.value)


def test_duplicate_or_missing_cameras(tmp_path):
    path = tmp_path / "cameras.json"
    entry = {"name": "c", "K": np.eye(3).tolist(), "R": np.eye(3).tolist(), "t": [0, 0, 1], "width": 4, "height": 4}
    path.write_text(json.dumps({"cameras": [entry, entry]}))
    with pytest.raises(InputError, match="repeat"):
        read_cameras(path)
    path.write_text(json.dumps({"cameras": []}))
    with pytest.raises(InputError, match="empty"):
        read_cameras(path)
    path.write_text(json.dumps([entry]))
    with pytest.raises(InputError, match="expected"):
        read_cameras(path)
