"""Per-frame preparation of the ``kinematic`` input (outliers, normals)."""

import numpy as np
from kinematic_shapes import _blob_sequence

from fourd.methods import kinematic as K
from fourd.methods.kinematic.frames import _prepare_frame
from fourd.sequence import Frame, PointCloudSequence


def test_frames_prepared_on_threads_are_those_prepared_one_by_one():
    blob, seq = _blob_sequence(frames=5)
    # outliers, so that the cleaning has something to drop
    rng = np.random.default_rng(1)
    frames = [
        Frame(points=np.vstack([f.points, rng.uniform(-3, 3, size=(40, 3))]), time=f.time)
        for f in seq.frames
    ]
    seq = PointCloudSequence(frames)
    options = K.Options()
    points, normals = K.prepare_frames(seq, options)
    assert len(points) == len(normals) == len(seq)
    for frame, p, n in zip(seq.frames, points, normals, strict=True):
        alone_p, alone_n = _prepare_frame(frame, options)
        assert len(p) < len(frame.points)
        np.testing.assert_array_equal(p, alone_p)
        np.testing.assert_array_equal(n, alone_n)
        # outward normals of the blob
        assert np.mean(np.einsum("ij,ij->i", n, blob.gradient(p, frame.time)[:, :3]) > 0) > 0.99
