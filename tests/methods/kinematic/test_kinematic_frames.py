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


def test_sparse_frames_are_densified_to_the_template_on_their_own_surface():
    from fourd.methods.kinematic.frames import densify_frames
    from fourd.methods.kinematic.options import DENSIFIED_POINTS_PER_VERTEX

    blob, seq = _blob_sequence(frames=3, count=800)
    options = K.Options(template_vertices=2000)
    points, normals = K.prepare_frames(seq, options)
    dense, dense_normals = densify_frames(points, normals, options)
    for frame, p, n in zip(seq.frames, dense, dense_normals, strict=True):
        assert abs(len(p) - DENSIFIED_POINTS_PER_VERTEX * 2000) < 0.25 * DENSIFIED_POINTS_PER_VERTEX * 2000
        # on the blob (its implicit is a signed distance near the surface), normals outward
        assert np.quantile(np.abs(blob.value(p, np.full(len(p), frame.time))), 0.95) < 0.02
        assert np.mean(np.einsum("ij,ij->i", n, blob.gradient(p, frame.time)[:, :3]) > 0) > 0.99
    # dense enough, or asked not to: the prepared frames themselves
    for options in (K.Options(template_vertices=500), K.Options(template_vertices=2000, densify=False)):
        same_points, same_normals = densify_frames(points, normals, options)
        assert same_points is points and same_normals is normals
