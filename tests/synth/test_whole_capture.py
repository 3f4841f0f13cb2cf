"""The synthetic whole capture (:mod:`fourd.synth.whole_capture`): ping-pong over the scene's
frames, each frame a scan of its truth frame, new noise on every pass."""

import numpy as np
from scipy.spatial import cKDTree

from fourd.synth.whole_capture import long_capture, pingpong


def test_pingpong_turns_at_both_ends():
    index = pingpong(12, 4)
    assert index.tolist() == [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1]
    assert np.abs(np.diff(index)).max() == 1


def test_every_frame_scans_its_truth_frame_with_fresh_noise():
    capture = long_capture(45, scene_name="squash-ball", resolution=48)
    assert len(capture.source) == 45 and capture.truth.frame_count == 20
    frames = capture.source.read(0, 45)
    diagonal = capture.truth.diagonal()
    for t in (0, 19, 21, 44):
        truth = capture.truth.vertices[capture.index[t]]
        distance = cKDTree(truth).query(frames[t].points)[0]
        assert np.median(distance) < 0.02 * diagonal, t
    # frames 17 and 21 show the same truth frame on two passes: other noise
    assert capture.index[17] == capture.index[21]
    assert not np.array_equal(frames[17].points[:50], frames[21].points[:50])
