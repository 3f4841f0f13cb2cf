"""Frames read when asked (:class:`fourd.frame_source.FrameSource`, :func:`open_sequence`)."""

import numpy as np
import pytest

import fourd
from fourd.errors import InputError
from fourd.frame_source import FrameSource
from fourd.io.frames import load_sequence, open_sequence, write_frames


def _sequence(count=6):
    rng = np.random.default_rng(1)
    return fourd.PointCloudSequence(
        tuple(fourd.Frame(rng.random((40 + t, 3)), time=2.0 * t) for t in range(count))
    )


def test_a_folder_is_read_frame_by_frame_as_loaded_whole(tmp_path):
    write_frames(_sequence(), tmp_path)
    whole, source = load_sequence(tmp_path), open_sequence(tmp_path)
    assert len(source) == len(whole) and source.names == whole.names
    np.testing.assert_array_equal(source.times, whole.times)
    part = source.read(2, 5)
    assert part.names == whole.names[2:5]
    for a, b in zip(part, whole.frames[2:5], strict=True):
        np.testing.assert_array_equal(a.points, b.points)
        assert a.time == b.time


def test_frames_are_read_only_when_asked(tmp_path):
    write_frames(_sequence(), tmp_path)
    (tmp_path / "frame_0004.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 9\n")
    source = open_sequence(tmp_path)  # the broken frame is not read yet
    assert len(source.read(0, 4)) == 4
    with pytest.raises(InputError, match="frame_0004.ply"):
        source.read(3, 6)


def test_slices_and_bad_sources():
    seq = _sequence()
    part = FrameSource.of(seq)[1::2]
    np.testing.assert_array_equal(part.times, [2.0, 6.0, 10.0])
    np.testing.assert_array_equal(part.read(1, 2)[0].points, seq.frames[3].points)
    with pytest.raises(InputError, match="increase strictly"):
        FrameSource(np.array([0.0, 1.0, 1.0]), (), seq.frames.__getitem__)
    with pytest.raises(InputError, match="not a fourd.Frame"):
        FrameSource(np.arange(2.0), (), lambda i: np.zeros((3, 3))).read(0, 1)


def test_a_folders_video_comes_with_its_frames_and_its_windows(tmp_path):
    filmed = fourd.synth.scan(
        fourd.synth.scene("rigid-turn", frames=4), resolution=24, video=True, video_resolution=16
    )
    write_frames(filmed, tmp_path)
    source = open_sequence(tmp_path)
    assert source.video is not None and source.video.frame_count == 4
    part = source.read(1, 3)
    assert part.video.frame_count == 2
    np.testing.assert_array_equal(part.video.image(0, 1), filmed.video.image(0, 2))
    np.testing.assert_array_equal(source[2:].video.image(1, 0), filmed.video.image(1, 2))
    assert FrameSource.of(filmed).read(0, 2).video.frame_count == 2
    # the cache key: the same for a rereading of the folder, another for another image
    from fourd.cache import stage_key

    key = stage_key(source.video.fingerprint())
    assert stage_key(open_sequence(tmp_path).video.fingerprint()) == key
    assert stage_key(source.video.select(slice(1, None)).fingerprint()) != key
    with pytest.raises(InputError, match="the video has 4 images per camera but there are 3"):
        FrameSource(source.times[:3], source.names[:3], source.read_frame, source.video)
