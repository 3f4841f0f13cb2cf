"""The fourd .npz written frame by frame (:func:`fourd.io.npz.npz_frames`): the same file as
:func:`write_npz`, and nothing on disk unless every frame arrived."""

import numpy as np
import pytest

import fourd
from fourd.errors import InputError
from fourd.io.npz import npz_frame_reader, npz_frames, npz_meshes, read_npz, write_npz


def _animation():
    rng = np.random.default_rng(0)
    vertices = rng.normal(size=(7, 5, 3))
    faces = np.array([[0, 1, 2], [2, 3, 4]])
    observed = rng.random((7, 5)) > 0.3
    return fourd.AnimatedMesh(
        faces, vertices, times=np.arange(7.0) * 0.5, observed=observed, rest=vertices[0]
    )


def test_frame_by_frame_reads_back_as_the_whole_file(tmp_path):
    anim = _animation()
    write_npz(tmp_path / "whole.npz", anim)
    with npz_frames(
        tmp_path / "frames.npz", faces=anim.faces, times=anim.times, rest=anim.rest
    ) as out:
        for a, b in ((0, 3), (3, 4), (4, 7)):
            out.write(anim.vertices[a:b], anim.observed[a:b])
    whole, frames = read_npz(tmp_path / "whole.npz"), read_npz(tmp_path / "frames.npz")
    for name in ("vertices", "faces", "times", "observed", "rest"):
        np.testing.assert_array_equal(getattr(frames, name), getattr(whole, name))


def test_an_incomplete_or_failed_write_leaves_nothing(tmp_path):
    anim = _animation()
    with pytest.raises(InputError, match="only 3 of 7 frames"):
        with npz_frames(
            tmp_path / "a.npz", faces=anim.faces, times=anim.times, rest=anim.rest
        ) as out:
            out.write(anim.vertices[:3], anim.observed[:3])
    with pytest.raises(ValueError, match="8 frames written to an output of 7"):
        with npz_frames(
            tmp_path / "b.npz", faces=anim.faces, times=anim.times, rest=anim.rest
        ) as out:
            out.write(np.concatenate([anim.vertices, anim.vertices[:1]]), np.ones((8, 5), bool))
    assert list(tmp_path.iterdir()) == []


def _meshes():
    rng = np.random.default_rng(1)
    meshes = tuple(
        (rng.normal(size=(n, 3)), rng.integers(0, n, size=(n - 2, 3))) for n in (5, 8, 6)
    )
    return fourd.MeshSequence(meshes, np.array([0.0, 0.5, 1.0]))


def test_a_mesh_sequence_frame_by_frame_reads_back_as_the_whole_file(tmp_path):
    seq = _meshes()
    write_npz(tmp_path / "whole.npz", seq)
    with npz_meshes(tmp_path / "frames.npz", times=seq.times) as out:
        for vertices, faces in seq.meshes:
            out.write(vertices, faces)
    whole, frames = read_npz(tmp_path / "whole.npz"), read_npz(tmp_path / "frames.npz")
    np.testing.assert_array_equal(frames.times, whole.times)
    for (v, f), (vw, fw) in zip(frames.meshes, whole.meshes, strict=True):
        np.testing.assert_array_equal(v, vw)
        np.testing.assert_array_equal(f, fw)


def test_a_mesh_sequence_missing_a_frame_leaves_nothing(tmp_path):
    seq = _meshes()
    with pytest.raises(InputError, match="only 2 of 3 frames"):
        with npz_meshes(tmp_path / "a.npz", times=seq.times) as out:
            for vertices, faces in seq.meshes[:2]:
                out.write(vertices, faces)
    assert not (tmp_path / "a.npz").exists()
    with pytest.raises(ValueError, match="4 frames written"):
        with npz_meshes(tmp_path / "b.npz", times=seq.times) as out:
            for vertices, faces in seq.meshes + seq.meshes[:1]:
                out.write(vertices, faces)
    assert not list(tmp_path.iterdir())


def test_the_frame_reader_gives_the_frames_of_either_writer_one_at_a_time(tmp_path):
    anim = _animation()
    write_npz(tmp_path / "whole.npz", anim)
    with npz_frames(tmp_path / "frames.npz", faces=anim.faces, times=anim.times) as out:
        out.write(anim.vertices, anim.observed)
    for name in ("whole.npz", "frames.npz"):
        with npz_frame_reader(tmp_path / name) as reader:
            frames = list(reader.frames())
            np.testing.assert_array_equal(reader.observed, anim.observed)
            np.testing.assert_array_equal(reader.faces, anim.faces)
            np.testing.assert_array_equal(reader.times, anim.times)
        assert all(f.shape == (5, 3) and f.dtype == np.float64 for f in frames)
        np.testing.assert_allclose(np.stack(frames), anim.vertices, atol=1e-6)  # float32 file
    assert reader.rest is None


def test_the_frame_reader_names_the_file_it_cannot_read(tmp_path):
    with pytest.raises(InputError, match="missing.npz"):
        with npz_frame_reader(tmp_path / "missing.npz"):
            pass
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(InputError, match="text.npz.*not a readable"):
        with npz_frame_reader(tmp_path / "text.npz"):
            pass
    write_npz(tmp_path / "meshes.npz", fourd.MeshSequence(((np.eye(3), np.array([[0, 1, 2]])),)))
    with pytest.raises(InputError, match="not a fourd animated mesh"):
        with npz_frame_reader(tmp_path / "meshes.npz"):
            pass
