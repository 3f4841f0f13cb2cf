"""Frame and sequence input: every format, folder conventions, and every kind of bad input."""

from __future__ import annotations

import json
import logging
import os

import numpy as np
import pytest
import trimesh

from fourd.errors import InputError
from fourd.io import frames as frame_files
from fourd.io.frames import load_sequence, natural_key, read_frame, write_frames
from fourd.io.meshfiles import write_obj, write_xyz
from fourd.io.ply import write_ply
from fourd.sequence import Frame, PointCloudSequence


def _cloud(count=64, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(count, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    return points, normals


# ------------------------------------------------------------------------------- formats


def test_read_frame_every_format(tmp_path):
    points, normals = _cloud()
    write_ply(tmp_path / "a.ply", points, normals=normals * 3.0)  # not unit: normalised on read
    write_obj(tmp_path / "b.obj", points, np.array([[0, 1, 2]]))
    write_xyz(tmp_path / "c.xyz", points, normals)
    (tmp_path / "d.pts").write_text(
        f"{len(points)}\n" + "".join(f"{x} {y} {z} 7 255 0 0\n" for x, y, z in points)
    )
    np.save(tmp_path / "e.npy", np.concatenate([points, normals], axis=1))
    np.savez(tmp_path / "f.npz", points=points, normals=normals)
    for name in ("a.ply", "b.obj", "c.xyz", "d.pts", "e.npy", "f.npz"):
        frame = read_frame(tmp_path / name, time=2.5)
        assert isinstance(frame, Frame)
        assert frame.time == 2.5
        assert np.abs(frame.points - points).max() <= 1e-6, name
        if name in ("a.ply", "c.xyz", "e.npy", "f.npz"):
            assert np.abs(frame.normals - normals).max() <= 1e-6, name
        else:
            assert frame.normals is None, name
    assert np.allclose(read_frame(tmp_path / "d.pts").colors, [1, 0, 0])


def test_trimesh_written_ply_and_obj_frames(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=1)
    sphere.export(tmp_path / "s.ply")
    sphere.export(tmp_path / "s.obj")
    for name in ("s.ply", "s.obj"):
        frame = read_frame(tmp_path / name)
        assert frame.points.shape == sphere.vertices.shape
        assert np.abs(frame.points - sphere.vertices).max() <= 1e-6


def test_zero_length_normals_are_dropped_with_a_warning(tmp_path, caplog):
    points, normals = _cloud()
    normals[5] = 0.0
    write_ply(tmp_path / "z.ply", points, normals=normals)
    with caplog.at_level(logging.WARNING, logger="fourd.io.frames"):
        frame = read_frame(tmp_path / "z.ply")
    assert frame.normals is None
    assert "z.ply" in caplog.text and "zero length" in caplog.text


def test_pts_with_count_header_and_xyz_comments(tmp_path):
    (tmp_path / "a.pts").write_text("3\n0 0 0\n1 0 0\n0 1 0\n")
    (tmp_path / "b.xyz").write_text("# a comment\n0,0,0\n\n1,0,0\n0,1,0\n")
    assert len(read_frame(tmp_path / "a.pts")) == 3
    assert np.array_equal(read_frame(tmp_path / "b.xyz").points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


# ------------------------------------------------------------------------------- folders


def test_natural_sort():
    names = ["frame_10.ply", "frame_2.ply", "frame_1.ply", "Frame_3.ply", "frame_100.ply"]
    assert sorted(names, key=natural_key) == [
        "frame_1.ply",
        "frame_2.ply",
        "Frame_3.ply",
        "frame_10.ply",
        "frame_100.ply",
    ]


def test_folder_order_ignored_files_times_and_fixed_sensors(tmp_path):
    for i in (10, 2, 1):
        np.save(tmp_path / f"frame_{i}.npy", np.full((5, 3), float(i)) + np.eye(5, 3))
    (tmp_path / ".hidden.ply").write_text("junk")
    (tmp_path / "truth.npz").write_bytes(b"not even an npz")
    (tmp_path / "truth").mkdir()
    (tmp_path / "times.txt").write_text("0.5\n# comment\n0.75 1.5\n")
    (tmp_path / "sensors.json").write_text(json.dumps({"sensors": [[0, 0, 5], [5, 0, 0]]}))
    seq = load_sequence(tmp_path)
    assert seq.names == ("frame_1.npy", "frame_2.npy", "frame_10.npy")
    assert [f.points[4, 0] for f in seq] == [1.0, 2.0, 10.0]
    assert np.array_equal(seq.times, [0.5, 0.75, 1.5])
    assert all(np.array_equal(f.sensors, [[0, 0, 5], [5, 0, 0]]) for f in seq)


def test_per_frame_sensors(tmp_path):
    for i in range(2):
        np.save(tmp_path / f"f{i}.npy", np.eye(4, 3) + i)
    (tmp_path / "sensors.json").write_text(
        json.dumps({"frames": [[[0, 0, 1]], [[0, 0, 2], [1, 1, 1]]]})
    )
    seq = load_sequence(tmp_path)
    assert seq[0].sensors.shape == (1, 3) and seq[1].sensors.shape == (2, 3)
    assert seq[1].sensors[0, 2] == 2.0


def test_single_npz_sequence_and_single_file(tmp_path):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(4, 30, 3))
    normals = points / np.linalg.norm(points, axis=2, keepdims=True)
    np.savez(
        tmp_path / "seq.npz",
        points=points,
        normals=normals,
        times=[0.0, 0.1, 0.2, 0.4],
        sensors=[[0, 0, 3]],
    )
    seq = load_sequence(tmp_path / "seq.npz")
    assert len(seq) == 4
    assert np.allclose(seq.times, [0, 0.1, 0.2, 0.4])
    assert np.allclose(seq[3].points, points[3]) and np.allclose(seq[3].normals, normals[3])
    assert np.array_equal(seq[2].sensors, [[0, 0, 3]])
    write_ply(tmp_path / "one.ply", points[0])
    single = load_sequence(tmp_path / "one.ply")
    assert len(single) == 1 and np.allclose(single[0].points, points[0], atol=1e-6)


def test_write_frames_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    frames = []
    for t in range(3):
        points = rng.normal(size=(40, 3))
        frames.append(
            Frame(
                points,
                normals=points / np.linalg.norm(points, axis=1, keepdims=True),
                colors=rng.random((40, 3)),
                sensors=np.array([[0.0, 0.0, 4.0]]),
                time=0.1 * t,
            )  # fmt: skip
        )
    seq = PointCloudSequence(tuple(frames))
    for fmt in ("ply", "npy", "xyz"):
        out = tmp_path / f"scans_{fmt}"
        write_frames(seq, out, format=fmt)
        back = load_sequence(out)
        assert len(back) == 3
        assert np.allclose(back.times, seq.times)
        for a, b in zip(seq, back, strict=True):
            assert np.abs(a.points - b.points).max() <= 1e-6
            assert np.abs(a.normals - b.normals).max() <= 1e-6
            assert np.array_equal(b.sensors, a.sensors)
    assert json.loads((tmp_path / "scans_ply" / "sensors.json").read_text()) == {
        "sensors": [[0.0, 0.0, 4.0]]
    }
    moving = PointCloudSequence(
        tuple(Frame(f.points, sensors=f.sensors + i, time=f.time) for i, f in enumerate(frames))
    )
    write_frames(moving, tmp_path / "moving")
    assert "frames" in json.loads((tmp_path / "moving" / "sensors.json").read_text())
    assert np.array_equal(load_sequence(tmp_path / "moving")[2].sensors, [[2.0, 2.0, 6.0]])


# ----------------------------------------------------------------------------- bad input


def _three_frames(folder):
    folder.mkdir(exist_ok=True)
    for i in range(3):
        np.save(folder / f"frame_{i}.npy", np.eye(4, 3) + i)
    return folder


def _raises(path, *, match_name: str, words: str = ""):
    with pytest.raises(InputError) as info:
        load_sequence(path)
    message = str(info.value)
    assert match_name in message, message
    assert words in message, message
    return message


def test_missing_path(tmp_path):
    _raises(tmp_path / "nowhere", match_name="nowhere", words="does not exist")


def test_empty_folder(tmp_path):
    folder = tmp_path / "empty_scans"
    folder.mkdir()
    (folder / "times.txt").write_text("")
    _raises(folder, match_name="empty_scans", words="no frame files")


def test_zero_point_frames(tmp_path):
    folder = _three_frames(tmp_path / "s")
    np.save(folder / "frame_1.npy", np.zeros((0, 3)))
    _raises(folder, match_name="frame_1.npy", words="zero points")
    (folder / "frame_1.npy").unlink()
    write_ply(folder / "frame_1.ply", np.zeros((0, 3)))
    _raises(folder, match_name="frame_1.ply", words="zero points")
    (folder / "frame_1.ply").unlink()
    (folder / "frame_1.xyz").write_text("# nothing\n")
    _raises(folder, match_name="frame_1.xyz", words="zero points")


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_coordinates(tmp_path, value):
    folder = _three_frames(tmp_path / "s")
    points = np.eye(4, 3)
    points[2, 1] = value
    write_ply(folder / "frame_2.ply", points)
    (folder / "frame_2.npy").unlink()
    _raises(folder, match_name="frame_2.ply", words="NaN or infinite")
    np.savez(tmp_path / "seq.npz", points=np.stack([np.eye(4, 3), points]))
    _raises(tmp_path / "seq.npz", match_name="seq.npz", words="NaN or infinite")


def test_truncated_and_malformed_ply_in_a_folder(tmp_path):
    folder = _three_frames(tmp_path / "s")
    write_ply(folder / "frame_5.ply", np.random.default_rng(0).normal(size=(100, 3)))
    data = (folder / "frame_5.ply").read_bytes()
    (folder / "frame_5.ply").write_bytes(data[: len(data) - 7])
    _raises(folder, match_name="frame_5.ply", words="truncated")
    (folder / "frame_5.ply").write_bytes(data.replace(b"format", b"fromat"))
    _raises(folder, match_name="frame_5.ply", words="malformed PLY header")


def test_unknown_extension(tmp_path):
    folder = _three_frames(tmp_path / "s")
    (folder / "points.pcd").write_text("hello")
    _raises(folder, match_name="points.pcd", words="unknown file type")
    with pytest.raises(InputError, match="scan.stl"):
        read_frame(_touch(tmp_path / "scan.stl"))


def _touch(path):
    path.write_text("x")
    return path


@pytest.mark.parametrize("shape", [(4, 4), (4, 2), (4,), (2, 4, 3, 1)])
def test_bad_array_dimensions(tmp_path, shape):
    folder = _three_frames(tmp_path / "s")
    np.save(folder / "frame_1.npy", np.ones(shape))
    _raises(folder, match_name="frame_1.npy")


def test_mixed_point_dimensions(tmp_path):
    folder = _three_frames(tmp_path / "s")
    np.save(
        folder / "frame_2.npy",
        np.concatenate([np.eye(4, 3), np.tile([[0, 0, 1.0]], (4, 1))], axis=1),
    )
    _raises(folder, match_name="frame_2.npy", words="mixed point dimensions")
    xyz = tmp_path / "x"
    xyz.mkdir()
    (xyz / "a_1.xyz").write_text("0 0 0\n1 0 0\n")
    (xyz / "a_2.xyz").write_text("0 0\n1 0\n")
    _raises(xyz, match_name="a_2.xyz", words="columns")
    (xyz / "a_2.xyz").write_text("0 0 0\n1 0\n")
    _raises(xyz, match_name="a_2.xyz", words="different numbers of columns")


def test_times_txt_problems(tmp_path):
    folder = _three_frames(tmp_path / "s")
    (folder / "times.txt").write_text("0\n1\n")
    _raises(folder, match_name="times.txt", words="2 times but there are 3 frames")
    (folder / "times.txt").write_text("0\n1\n1\n")
    _raises(folder, match_name="times.txt", words="increase strictly")
    (folder / "times.txt").write_text("0\n1\nlater\n")
    _raises(folder, match_name="times.txt", words="'later' is not a number")
    (folder / "times.txt").write_text("0\n1\nnan\n")
    _raises(folder, match_name="times.txt", words="finite")


@pytest.mark.parametrize(
    "content",
    [
        "{not json",
        "[1, 2, 3]",
        '{"cameras": [[0, 0, 0]]}',
        '{"sensors": [[0, 0]]}',
        '{"sensors": [["a", 0, 0]]}',
        '{"sensors": [[0, 0, NaN]]}',
        '{"frames": [[[0, 0, 1]]]}',
        '{"frames": 3}',
    ],
)
def test_malformed_sensors_json(tmp_path, content):
    folder = _three_frames(tmp_path / "s")
    (folder / "sensors.json").write_text(content)
    _raises(folder, match_name="sensors.json")


def test_unreadable_file(tmp_path, monkeypatch):
    folder = _three_frames(tmp_path / "s")
    write_ply(folder / "frame_1.ply", np.eye(4, 3))
    (folder / "frame_1.npy").unlink()
    original = frame_files.read_ply

    def denied(path, **kwargs):
        if path.name == "frame_1.ply":
            raise PermissionError(13, "Permission denied", str(path))
        return original(path, **kwargs)

    monkeypatch.setattr(frame_files, "read_ply", denied)
    _raises(folder, match_name="frame_1.ply", words="Permission denied")


@pytest.mark.skipif(
    os.name != "posix" or os.geteuid() == 0, reason="file permissions do not bind root"
)
def test_unreadable_file_by_permissions(tmp_path):
    folder = _three_frames(tmp_path / "s")
    (folder / "frame_1.npy").chmod(0)
    try:
        _raises(folder, match_name="frame_1.npy", words="cannot be read")
    finally:
        (folder / "frame_1.npy").chmod(0o644)


@pytest.mark.parametrize(
    "name, content",
    [
        ("bad.npy", b"\x93NUMPY garbage"),
        ("bad.npz", b"PK\x03\x04 not a zip"),
        ("bad.obj", b"v 1 2\n"),
        ("bad.obj", b"v 1 2 x\n"),
        ("bad.pts", b"12\n1 2 3\n"),
        ("bad.xyz", b"1 2 3 4 5\n"),
    ],
)
def test_garbage_files(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(InputError, match=name.replace(".", r"\.")):
        read_frame(path)


def test_npz_problems(tmp_path):
    np.savez(tmp_path / "nopoints.npz", vertices=np.eye(3))
    _raises(tmp_path / "nopoints.npz", match_name="nopoints.npz", words="no 'points'")
    np.savez(tmp_path / "times.npz", points=np.ones((2, 4, 3)), times=[1.0, 0.0])
    _raises(tmp_path / "times.npz", match_name="times.npz", words="increase strictly")
    np.savez(tmp_path / "objects.npz", points=np.array(["a", "b", "c"]).reshape(1, 3))
    _raises(tmp_path / "objects.npz", match_name="objects.npz", words="not numbers")
    folder = _three_frames(tmp_path / "s")
    np.savez(folder / "frame_3.npz", points=np.ones((2, 4, 3)))
    _raises(folder, match_name="frame_3.npz", words="sequence of 2 frames")


def test_shared_point_sequence_reads_in_original_units(tmp_path):
    from fourd.synth.data import load_shared, shared_data_dir

    folder = shared_data_dir()
    if folder is None or not (folder / "dfaust-hopping.npz").is_file():
        pytest.skip("../shared/data/dfaust-hopping.npz is not available")
    seq = load_sequence(folder / "dfaust-hopping.npz")
    truth = load_shared("dfaust-hopping")
    assert len(seq) == truth.frame_count == 17
    assert np.abs(seq[16].points - truth.vertices[16]).max() <= 1e-9
    subset = PointCloudSequence(tuple(Frame(f.points[::50], time=f.time) for f in seq.frames[:3]))
    write_frames(subset, tmp_path / "hop")
    back = load_sequence(tmp_path / "hop")
    assert np.abs(back[2].points - truth.vertices[2, ::50]).max() <= 1e-6


def test_notes_logs_and_other_files_beside_the_frames_are_skipped_but_unknown_geometry_stops(tmp_path, caplog):
    rng = np.random.default_rng(0)
    for k in range(2):
        np.save(tmp_path / f"frame_{k}.npy", rng.normal(size=(50, 3)))
    for name in ("notes.md", "rig.json", "capture.log", "table.csv", "photo.png", "readme.txt"):
        (tmp_path / name).write_text("not a frame")
    with caplog.at_level(logging.INFO, logger="fourd"):
        seq = load_sequence(tmp_path)
    assert len(seq) == 2
    assert "skipped" in caplog.text and "notes.md" in caplog.text and "rig.json" in caplog.text
    (tmp_path / "frame_2.stl").write_text("solid x")
    with pytest.raises(InputError, match=r"frame_2\.stl.*unknown file type '\.stl'"):
        load_sequence(tmp_path)


def test_frames_with_faces_are_per_frame_meshes(tmp_path):
    """A PLY or OBJ frame with faces is a per-frame mesh (``Frame.faces``); ``write_frames``
    writes the faces back, in double precision."""
    box = trimesh.creation.box()
    vertices = np.asarray(box.vertices) + 1e-9  # a digit float32 would lose
    frames = tuple(Frame(vertices + t, faces=box.faces, time=t) for t in range(2))
    write_frames(PointCloudSequence(frames), tmp_path / "meshes")
    seq = load_sequence(tmp_path / "meshes")
    for t, frame in enumerate(seq):
        np.testing.assert_array_equal(frame.faces, box.faces)
        np.testing.assert_array_equal(frame.points, vertices + t)
    with pytest.raises(InputError, match="written as ply"):
        write_frames(PointCloudSequence(frames), tmp_path / "xyz", format="xyz")
    write_obj(tmp_path / "mesh.obj", vertices, box.faces)
    np.testing.assert_array_equal(read_frame(tmp_path / "mesh.obj").faces, box.faces)
    write_ply(tmp_path / "cloud.ply", vertices)
    assert read_frame(tmp_path / "cloud.ply").faces is None
    with pytest.raises(InputError, match="outside the frame's 8 points"):
        Frame(vertices, faces=box.faces + 1)
    with pytest.raises(InputError, match=r"shape \[F, 3\]"):
        Frame(vertices, faces=np.zeros((2, 4), dtype=int))
