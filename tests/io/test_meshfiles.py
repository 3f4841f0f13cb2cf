"""OBJ and XYZ/PTS text files: the vectorised path and the line-by-line path agree."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from fourd.errors import InputError
from fourd.io.meshfiles import read_obj, read_xyz, write_obj, write_xyz

SQUARE = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"


@pytest.mark.parametrize(
    "faces",
    [
        "f 1 2 3 4\n",  # a quad: fast path
        "f 1/1/1 2/2/2 3/3/3 4/4/4\n",  # texture/normal indices: fast path
        "f 1//1 2//2 3//3 4//4\n",
        "f -4 -3 -2 -1\n",  # relative indices: line-by-line path
        "f 1 2 3\nf 1 3 4\n",
    ],
)
def test_obj_face_syntaxes(tmp_path, faces):
    path = tmp_path / "square.obj"
    path.write_text("# square\n" + SQUARE + "vn 0 0 1\n" + faces)
    mesh = read_obj(path)
    assert np.array_equal(mesh.vertices[2], [1, 1, 0])
    assert sorted(map(tuple, mesh.faces.tolist())) == [(0, 1, 2), (0, 2, 3)]


def test_obj_mixed_polygons_and_colours(tmp_path):
    path = tmp_path / "mixed.obj"
    path.write_text(
        "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\nv 2 2 2 0 0 0\nf 1 2 3\nf 1 2 3 4\n"
    )
    mesh = read_obj(path)
    assert len(mesh.faces) == 3
    assert np.array_equal(mesh.colors[1], [0, 1, 0])


def test_obj_round_trip_with_trimesh(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    write_obj(tmp_path / "ours.obj", sphere.vertices, sphere.faces)
    theirs = trimesh.load(tmp_path / "ours.obj", process=False)
    assert np.array_equal(theirs.faces, sphere.faces)
    sphere.export(tmp_path / "theirs.obj")
    ours = read_obj(tmp_path / "theirs.obj")
    assert np.array_equal(ours.faces, sphere.faces)
    assert np.abs(ours.vertices - sphere.vertices).max() <= 1e-6


@pytest.mark.parametrize(
    "content, words",
    [
        ("v 0 0\n", "3 coordinates"),
        ("v 0 0 zero\n", "not a number"),
        (SQUARE + "f 1 2\n", "at least 3 corners"),
        (SQUARE + "f 1 2 9\n", "outside the 4 vertices"),
        (SQUARE + "f 1 two 3\n", "malformed face"),
    ],
)
def test_obj_errors(tmp_path, content, words):
    path = tmp_path / "bad_mesh.obj"
    path.write_text(content)
    with pytest.raises(InputError, match=words) as info:
        read_obj(path)
    assert "bad_mesh.obj" in str(info.value)


def test_xyz_and_pts_variants(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(20, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    write_xyz(tmp_path / "a.xyz", points, normals)
    table = read_xyz(tmp_path / "a.xyz")
    assert table.columns == 6 and np.abs(table.normals - normals).max() <= 1e-8
    (tmp_path / "b.pts").write_text("// scanner export\n2\n0 0 0 10\n1 1 1 20\n")
    assert read_xyz(tmp_path / "b.pts").points.shape == (2, 3)
    (tmp_path / "c.pts").write_text("2\n0 0 0 10 255 0 0\n1 1 1 20 0 0 255\n")
    assert np.array_equal(read_xyz(tmp_path / "c.pts").colors, [[1, 0, 0], [0, 0, 1]])
    (tmp_path / "d.xyz").write_text("0 0 0 10\n")
    with pytest.raises(InputError, match=r"d\.xyz.*4 columns"):
        read_xyz(tmp_path / "d.xyz")
