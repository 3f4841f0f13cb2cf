import json

import numpy as np
import pytest
from PIL import Image

import fourd
from fourd.appearance.cameras import look_at
from fourd.errors import InputError
from fourd.io.frames import write_frames
from fourd.io.video import Video, read_video, write_video
from fourd.sequence import Frame, PointCloudSequence


def _cameras(width=40, height=30):
    return (
        look_at("left", [-2, 0, 3], [0, 0, 0], [0, 1, 0], focal=40, width=width, height=height),
        look_at("right", [2, 0, 3], [0, 0, 0], [0, 1, 0], focal=40, width=width, height=height),
    )


def _capture(tmp_path, frames=3, width=40, height=30):
    """A folder with ``frames`` point frames and a two-camera video whose image ``(c, t)`` is
    filled with the value ``10 * c + t``."""
    rng = np.random.default_rng(0)
    seq = PointCloudSequence(tuple(Frame(rng.random((30, 3)), time=t) for t in range(frames)))
    images = np.zeros((2, frames, height, width, 3), np.uint8)
    for c in range(2):
        for t in range(frames):
            images[c, t] = 10 * c + t
    video = Video.from_arrays(_cameras(width, height), images)
    folder = tmp_path / "capture"
    write_frames(PointCloudSequence(seq.frames, video=video), folder)
    return folder


def test_folder_round_trip_reads_images_lazily(tmp_path):
    folder = _capture(tmp_path)
    names = sorted(p.name for p in (folder / "video" / "left").iterdir())
    assert names == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    seq = fourd.load_sequence(folder)
    video = seq.video
    assert video.names == ("left", "right") and video.frame_count == 3
    assert all(isinstance(item, type(folder)) for row in video.images for item in row)  # paths
    image = video.image("right", 2)
    assert image.dtype == np.uint8 and image.shape == (30, 40, 3)
    assert np.all(image == 12) and np.all(video.image(0, 1) == 1)
    np.testing.assert_allclose(video.cameras[1].K, _cameras()[1].K)
    np.testing.assert_allclose(video.cameras[1].R, _cameras()[1].R)
    assert seq[1:].video.frame_count == 2 and np.all(seq[1:].video.image(0, 0) == 1)


def test_folder_without_video_has_none(tmp_path):
    rng = np.random.default_rng(0)
    write_frames(PointCloudSequence((Frame(rng.random((10, 3))),)), tmp_path / "plain")
    assert fourd.load_sequence(tmp_path / "plain").video is None


def test_missing_image_names_the_camera_folder(tmp_path):
    folder = _capture(tmp_path)
    (folder / "video" / "right" / "frame_0001.png").unlink()
    with pytest.raises(InputError) as info:
        fourd.load_sequence(folder)
    assert "right" in str(info.value) and "2 images" in str(info.value) and "3 frames" in str(info.value)


def test_unreadable_image_names_it(tmp_path):
    folder = _capture(tmp_path)
    bad = folder / "video" / "left" / "frame_0002.png"
    bad.write_bytes(b"not a png at all")
    with pytest.raises(InputError) as info:
        fourd.load_sequence(folder)
    assert str(bad) in str(info.value) and "\n" not in str(info.value)


def test_truncated_image_fails_when_decoded(tmp_path):
    folder = _capture(tmp_path, width=64, height=48)
    path = folder / "video" / "left" / "frame_0000.png"
    rng = np.random.default_rng(1)
    Image.fromarray((rng.random((48, 64, 3)) * 255).astype(np.uint8)).save(path)
    path.write_bytes(path.read_bytes()[:200])  # header intact, data cut
    video = fourd.load_sequence(folder).video  # headers are fine
    with pytest.raises(InputError) as info:
        video.image(0, 0)
    assert str(path) in str(info.value)


def test_image_size_must_match_cameras_json(tmp_path):
    folder = _capture(tmp_path)
    path = folder / "video" / "left" / "frame_0001.png"
    Image.fromarray(np.zeros((31, 40, 3), np.uint8)).save(path)
    with pytest.raises(InputError) as info:
        fourd.load_sequence(folder)
    message = str(info.value)
    assert str(path) in message and "40x31" in message and "40x30" in message


def test_bad_cameras_json(tmp_path):
    folder = _capture(tmp_path)
    path = folder / "cameras.json"
    data = json.loads(path.read_text())
    data["cameras"][0]["R"] = [[1, 0, 0], [0, 2, 0], [0, 0, 1]]
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match="not a rotation") as info:
        fourd.load_sequence(folder)
    assert str(path) in str(info.value)
    path.write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        fourd.load_sequence(folder)
    del data["cameras"][0]["K"]
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match="lacks K"):
        fourd.load_sequence(folder)


def test_camera_without_folder_and_cameras_without_video(tmp_path):
    folder = _capture(tmp_path)
    (folder / "video" / "right").rename(folder / "video" / "other")
    with pytest.raises(InputError, match="no image folder") as info:
        fourd.load_sequence(folder)
    assert "right" in str(info.value)
    for path in (folder / "video").rglob("*.png"):
        path.unlink()
    for sub in (folder / "video").iterdir():
        sub.rmdir()
    (folder / "video").rmdir()
    with pytest.raises(InputError, match="no video/ folder"):
        fourd.load_sequence(folder)


def test_sequence_and_video_frame_counts_must_agree(tmp_path):
    frames = tuple(Frame(np.eye(3), time=t) for t in range(2))
    video = Video.from_arrays(_cameras(), np.zeros((2, 3, 30, 40, 3), np.uint8))
    with pytest.raises(InputError, match="3 images per camera but there are 2 frames"):
        PointCloudSequence(frames, video=video)
    with pytest.raises(InputError, match="is 40x31"):
        Video.from_arrays(_cameras(), np.zeros((2, 1, 31, 40, 3), np.uint8))


def test_write_video_names_and_reads_back(tmp_path):
    video = Video.from_arrays(_cameras(), np.full((2, 2, 30, 40, 3), 7, np.uint8))
    (tmp_path / "v").mkdir()
    write_video(tmp_path / "v", video)
    assert sorted(p.name for p in (tmp_path / "v" / "video" / "left").iterdir()) == [
        "0000.png",
        "0001.png",
    ]
    back = read_video(tmp_path / "v", frame_count=2)
    assert np.all(back.image("left", 1) == 7)
    with pytest.raises(InputError, match="no camera named"):
        back.image("middle", 0)
