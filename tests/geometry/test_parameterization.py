"""UV atlases (xatlas), seam splitting and indexed corners."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from fourd.errors import InputError
from fourd.geometry.parameterization import indexed_corners, split_seams, uv_atlas


def _signed_areas_2d(points, faces):
    a, b, c = (points[faces[:, i]] for i in range(3))
    (x1, y1), (x2, y2) = (b - a).T, (c - a).T
    return 0.5 * (x1 * y2 - y1 * x2)


def _triangle_areas(points, faces):
    if points.shape[1] == 2:
        return np.abs(_signed_areas_2d(points, faces))
    a, b, c = (points[faces[:, i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1)


def test_uv_atlas_of_a_sphere_is_an_injective_packing_in_the_unit_square():
    pytest.importorskip("xatlas", reason="xatlas (the fourd[uv] extra) is not installed")
    sphere = trimesh.creation.icosphere(subdivisions=2)
    uv = uv_atlas(sphere.vertices * 1000 + 5000, sphere.faces, resolution=128)  # far, big
    assert uv.shape == (len(sphere.faces), 3, 2)
    assert uv.min() >= 0 and uv.max() <= 1 and uv.max() > 0.9
    seams = split_seams(sphere.faces, uv, len(sphere.vertices))
    flat = _triangle_areas(seams.uv, seams.faces)
    # every triangle keeps a real area in the atlas, and charts do not overlap: the areas
    # add up to at most the unit square (the packing leaves gaps)
    assert flat.min() > 0 and flat.sum() <= 1.0
    # the charts keep relative size: flattened area proportional to surface area (LSCM has
    # some distortion, so a loose bound)
    ratio = flat / _triangle_areas(sphere.vertices, sphere.faces)
    assert np.percentile(ratio, 90) / np.percentile(ratio, 10) < 2.0
    # counter-clockwise like the faces (seen from outside): no chart mirrored
    assert (_signed_areas_2d(seams.uv, seams.faces) > 0).all()


def test_uv_atlas_without_xatlas_says_what_to_install(monkeypatch):
    monkeypatch.setitem(__import__("sys").modules, "xatlas", None)  # as if not installed
    with pytest.raises(InputError, match=r"pip install 'fourd\[uv\]'"):
        uv_atlas(np.eye(3), np.array([[0, 1, 2]]))


def test_uv_atlas_refuses_a_mesh_without_faces():
    pytest.importorskip("xatlas", reason="xatlas (the fourd[uv] extra) is not installed")
    with pytest.raises(InputError, match="needs faces"):
        uv_atlas(np.eye(3), np.zeros((0, 3), int))


def test_split_seams_keeps_every_vertex_and_duplicates_only_seams():
    box = trimesh.creation.box()
    faces = box.faces
    # one UV island per face pair of the cube: vertices on cube edges get several UVs
    rng = np.random.default_rng(0)
    island = rng.random((len(faces) // 2, 2))
    uv = np.repeat(island, 2, axis=0)[:, None, :] + 0.01 * np.arange(3)[None, :, None]
    uv = np.repeat(uv, 1, axis=0)
    seams = split_seams(faces, uv, len(box.vertices))
    n = len(box.vertices)
    assert np.array_equal(seams.vertex[:n], np.arange(n))
    assert np.array_equal(seams.vertex[seams.faces], faces)  # same corners, same vertices
    assert np.allclose(seams.uv[seams.faces], uv)  # every corner keeps its own UV
    # as many vertices as distinct (vertex, uv) pairs
    pairs = {(v, *map(float, t)) for v, t in zip(faces.ravel(), uv.reshape(-1, 2), strict=True)}
    assert len(seams.vertex) == len(pairs)


def test_split_seams_without_seams_changes_nothing():
    sphere = trimesh.creation.icosphere(subdivisions=1)
    per_vertex = sphere.vertices[:, :2] * 0.5 + 0.5
    seams = split_seams(sphere.faces, per_vertex[sphere.faces], len(sphere.vertices))
    assert np.array_equal(seams.faces, sphere.faces)
    assert np.allclose(seams.uv, per_vertex)


def test_indexed_corners_rebuild_the_corners():
    rng = np.random.default_rng(1)
    uv = rng.integers(0, 4, size=(10, 3, 2)) / 4
    values, indices = indexed_corners(uv)
    assert len(values) == len(np.unique(uv.reshape(-1, 2), axis=0))
    assert np.array_equal(values[indices].reshape(uv.shape), uv)
