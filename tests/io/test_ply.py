"""PLY reading and writing: every encoding, independent writers, malformed files, speed."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
import trimesh

from fourd.errors import InputError
from fourd.io.ply import read_ply, write_ply


def _cloud(count=200, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(count, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    colors = rng.random((count, 3))
    return points, normals, colors


@pytest.mark.parametrize("binary", [True, False], ids=["binary", "ascii"])
@pytest.mark.parametrize("big_endian", [False, True], ids=["le", "be"])
@pytest.mark.parametrize("double", [False, True], ids=["float", "double"])
def test_round_trip_every_encoding(tmp_path, binary, big_endian, double):
    points, normals, colors = _cloud()
    faces = np.array([[0, 1, 2], [2, 3, 4]])
    path = tmp_path / "cloud.ply"
    write_ply(
        path,
        points,
        normals=normals,
        colors=colors,
        faces=faces,
        binary=binary,
        big_endian=big_endian,
        double=double,
    )
    header = path.read_bytes()[:200]
    expected = (
        b"ascii"
        if not binary
        else (b"binary_big_endian" if big_endian else b"binary_little_endian")
    )
    assert expected in header
    assert (b"double x" if double else b"float x") in header
    mesh = read_ply(path)
    tolerance = 1e-12 if double else 1e-6
    assert np.abs(mesh.vertices - points).max() <= tolerance * 10
    assert np.abs(mesh.normals - normals).max() <= tolerance * 10
    assert np.abs(mesh.colors - colors).max() <= 0.5 / 255 + 1e-9
    assert np.array_equal(mesh.faces, faces)


def test_trimesh_written_mesh_binary_and_ascii(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    for encoding in ("binary", "ascii"):
        path = tmp_path / f"sphere_{encoding}.ply"
        sphere.export(path, encoding=encoding)
        mesh = read_ply(path)
        assert mesh.vertices.shape == sphere.vertices.shape
        assert np.abs(mesh.vertices - sphere.vertices).max() <= 1e-6
        assert np.array_equal(mesh.faces, sphere.faces)


def test_trimesh_written_point_cloud_with_rgba(tmp_path):
    points, _, colors = _cloud(50, seed=3)
    rgba = np.concatenate([np.round(colors * 255), np.full((50, 1), 255)], axis=1).astype(np.uint8)
    path = tmp_path / "pc.ply"
    trimesh.PointCloud(points, colors=rgba).export(path)
    mesh = read_ply(path)
    assert np.abs(mesh.vertices - points).max() <= 1e-6
    assert np.abs(mesh.colors - rgba[:, :3] / 255.0).max() <= 1e-9
    assert (
        "alpha" in mesh.properties
    )  # extra property kept in properties, not confused with colours


def test_hand_built_big_endian_double_with_extras_and_quads(tmp_path):
    """A file built byte by byte with struct (independent of our writer)."""
    header = (
        b"ply\nformat binary_big_endian 1.0\ncomment hand made\n"
        b"element vertex 4\nproperty double x\nproperty double y\nproperty double z\n"
        b"property float confidence\nproperty double nx\nproperty double ny\nproperty double nz\n"
        b"property uchar red\nproperty uchar green\nproperty uchar blue\n"
        b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    rows = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    body = b"".join(struct.pack(">dddfdddBBB", *p, 0.5, 0, 0, 2.0, 255, 0, 51) for p in rows)
    body += struct.pack(">B4i", 4, 0, 1, 2, 3)
    path = tmp_path / "quad.ply"
    path.write_bytes(header + body)
    mesh = read_ply(path)
    assert np.array_equal(mesh.vertices, np.array(rows, float))
    assert np.allclose(mesh.normals, [[0, 0, 2.0]] * 4)
    assert np.allclose(mesh.colors, [[1.0, 0.0, 0.2]] * 4)
    assert np.array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])
    assert np.allclose(mesh.properties["confidence"], 0.5)


def test_ascii_mixed_polygons_and_float_colors(tmp_path):
    text = (
        "ply\r\nformat ascii 1.0\r\nelement vertex 5\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n"
        "property float red\r\nproperty float green\r\nproperty float blue\r\n"
        "element face 2\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
        "0 0 0 1 0 0\r\n1 0 0 0 1 0\r\n1 1 0 0 0 1\r\n0 1 0 0.5 0.5 0.5\r\n2 2 2 0 0 0\r\n"
        "3 0 1 2\r\n4 0 1 2 3\r\n"
    )
    path = tmp_path / "mixed.ply"
    path.write_text(text)
    mesh = read_ply(path)
    assert mesh.vertices.shape == (5, 3)
    assert np.allclose(mesh.colors[3], 0.5)
    assert len(mesh.faces) == 3
    assert sorted(map(tuple, mesh.faces.tolist())) == [(0, 1, 2), (0, 1, 2), (0, 2, 3)]


def test_binary_variable_length_faces_fall_back(tmp_path):
    header = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        b"element face 2\nproperty list uchar uint vertex_indices\nend_header\n"
    )
    body = (
        np.arange(12, dtype="<f4").tobytes()
        + struct.pack("<B3I", 3, 0, 1, 2)
        + struct.pack("<B4I", 4, 0, 1, 2, 3)
    )
    path = tmp_path / "var.ply"
    path.write_bytes(header + body)
    mesh = read_ply(path)
    assert len(mesh.faces) == 3
    assert mesh.faces.max() == 3


def _header(vertices=3, fmt="binary_little_endian"):
    return (
        f"ply\nformat {fmt} 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    ).encode()


@pytest.mark.parametrize(
    "content, words",
    [
        (b"", "not a PLY"),
        (b"solid stl\n", "not a PLY"),
        (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", "end_header"),
        (b"ply\nformat binary_middle_endian 1.0\nelement vertex 1\nend_header\n", "header line 2"),
        (
            b"ply\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n",
            "format",
        ),
        (b"ply\nformat ascii 1.0\nelement vertex three\nend_header\n", "header line 3"),
        (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "before any element"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quaternion x\nend_header\n",
            "header line 4",
        ),
        (b"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no 'vertex' element"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n",
            "no x, y, z",
        ),
        (_header(3) + np.zeros(8, "<f4").tobytes(), "truncated"),
        (_header(3, "ascii") + b"0 0 0\n1 1 1\n", "truncated"),
        (_header(2, "ascii") + b"0 0 0\n1 nope 1\n", "not a number"),
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
            b"element face 2\nproperty list uchar int vertex_indices\nend_header\n"
            + np.zeros(3, "<f4").tobytes()
            + b"\x03\x00",
            "truncated",
        ),
    ],
)
def test_malformed_files_raise_input_error_naming_the_file(tmp_path, content, words):
    path = tmp_path / "broken_scan.ply"
    path.write_bytes(content)
    with pytest.raises(InputError) as info:
        read_ply(path)
    assert "broken_scan.ply" in str(info.value)
    assert words in str(info.value)


def test_faces_indexing_missing_vertices_are_rejected(tmp_path):
    path = tmp_path / "bad_faces.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"
    )
    with pytest.raises(InputError, match="bad_faces.ply"):
        read_ply(path)
    assert len(read_ply(path, faces=False).vertices) == 3


def test_binary_read_of_100k_points_is_fast(tmp_path):
    points, normals, colors = _cloud(100_000, seed=1)
    path = tmp_path / "big.ply"
    write_ply(path, points, normals=normals, colors=colors)
    read_ply(path)  # warm the page cache
    best = min(_timed(lambda: read_ply(path, faces=False)) for _ in range(3))
    assert best < 0.5, f"reading 100k binary points took {best:.3f} s"


def _timed(function) -> float:
    start = time.perf_counter()
    function()
    return time.perf_counter() - start


def test_end_header_only_counts_at_the_start_of_a_line(tmp_path):
    path = tmp_path / "comment.ply"
    path.write_bytes(
        b"ply\nformat binary_little_endian 1.0\ncomment the header ends at end_header\n"
        b"element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
        + np.arange(6, dtype="<f4").tobytes()
    )
    assert np.array_equal(read_ply(path).vertices, np.arange(6.0).reshape(2, 3))
