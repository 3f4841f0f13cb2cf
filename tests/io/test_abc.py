"""Alembic output, checked with the alembic3d library's own reader, and read back by fourd."""

from __future__ import annotations

import builtins

import numpy as np
import pytest
import trimesh

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.abc import MESH_NAME, XFORM_NAME, read_abc, write_abc
from fourd.io.results import check_output, load_result, save


def _animation(frames=3, times=None) -> AnimatedMesh:
    sphere = trimesh.creation.icosphere(subdivisions=1)
    vertices = np.stack([sphere.vertices * (1 + 0.1 * t) + [0.3 * t, 0, 0] for t in range(frames)])
    observed = np.ones((frames, len(sphere.vertices)), bool)
    observed[1, :7] = False
    return AnimatedMesh(sphere.faces, vertices, times=times, observed=observed)


def _open(path):
    """The written mesh's schema, through alembic3d alone."""
    from alembic3d import Abc, AbcGeom

    archive = Abc.IArchive(str(path))
    xform = archive.getTop().getChild(XFORM_NAME)
    return archive, AbcGeom.IPolyMesh(xform, MESH_NAME).getSchema()


def _sample(schema, k):
    from alembic3d import Abc

    selector = Abc.ISampleSelector(schema.getTimeSampling().getSampleTime(k))
    sample = schema.getValue(selector)
    positions = np.array(sample.getPositions(), dtype=np.float64).reshape(-1, 3)
    indices = np.array(sample.getFaceIndices(), dtype=np.int64)
    counts = np.array(sample.getFaceCounts(), dtype=np.int64)
    normals = np.array(schema.getNormalsParam().getExpandedValue(selector).getVals()).reshape(-1, 3)
    return positions, indices, counts, normals


def test_animated_mesh_round_trip(tmp_path):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    from alembic3d import Abc, AbcGeom

    anim = _animation(frames=3)
    save(anim, tmp_path / "walk.abc", fps=24)
    archive, schema = _open(tmp_path / "walk.abc")
    assert schema.getNumSamples() == 3
    assert schema.getTopologyVariance() == AbcGeom.MeshTopologyVariance.kHomogenousTopology
    sampling = schema.getTimeSampling()
    assert sampling.getTimeSamplingType().isUniform()
    assert [sampling.getSampleTime(k) for k in range(3)] == pytest.approx([0, 1 / 24, 2 / 24])
    assert Abc.GetArchiveStartAndEndTime(archive) == pytest.approx((0.0, 2 / 24))
    info = Abc.GetArchiveInfo(archive)
    assert "fourd" in info["appName"] and info["dccFPS"] == 24.0
    for k in range(3):
        positions, indices, counts, normals = _sample(schema, k)
        assert np.abs(positions - anim.vertices[k]).max() <= 1e-6
        assert counts.tolist() == [3] * len(anim.faces)
        # Alembic winds clockwise: the file holds each triangle reversed
        assert np.array_equal(indices.reshape(-1, 3), anim.faces[:, ::-1])
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
        outward = np.einsum("ij,ij->i", normals, positions - positions.mean(axis=0))
        assert (outward > 0).all()
    back = load_result(tmp_path / "walk.abc")
    assert isinstance(back, AnimatedMesh)
    assert np.array_equal(back.faces, anim.faces)
    assert np.abs(back.vertices - anim.vertices).max() <= 1e-6
    assert back.times.tolist() == [0.0, 1.0, 2.0]  # the result's own times (fourdTimes)
    assert np.array_equal(back.observed, anim.observed)


def test_uneven_times_are_an_acyclic_sampling_in_seconds(tmp_path):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    anim = _animation(frames=3, times=[0.5, 0.54, 0.7])
    write_abc(tmp_path / "walk.abc", anim)
    _, schema = _open(tmp_path / "walk.abc")
    sampling = schema.getTimeSampling()
    assert sampling.getTimeSamplingType().isAcyclic()
    assert [sampling.getSampleTime(k) for k in range(3)] == pytest.approx([0.5, 0.54, 0.7])
    assert read_abc(tmp_path / "walk.abc").times.tolist() == [0.5, 0.54, 0.7]


def test_changing_topology_is_heterogeneous(tmp_path):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    from alembic3d import AbcGeom

    box = trimesh.creation.box()
    sphere = trimesh.creation.icosphere(subdivisions=1)
    empty = (np.zeros((0, 3)), np.zeros((0, 3), int))
    seq = MeshSequence(((box.vertices, box.faces), (sphere.vertices, sphere.faces), empty),
                       times=[0, 1, 3])
    save(seq, tmp_path / "split.abc")
    _, schema = _open(tmp_path / "split.abc")
    assert schema.getTopologyVariance() == AbcGeom.MeshTopologyVariance.kHeterogenousTopology
    assert [schema.getTimeSampling().getSampleTime(k) for k in range(3)] == pytest.approx(
        [0, 1 / 30, 3 / 30]
    )
    back = load_result(tmp_path / "split.abc")
    assert isinstance(back, MeshSequence) and back.times.tolist() == [0.0, 1.0, 3.0]
    for (v, f), (v2, f2) in zip(seq.meshes, back.meshes, strict=True):
        assert np.array_equal(f, f2) and v.shape == v2.shape
        assert np.abs(v - v2).max(initial=0) <= 1e-6


def test_z_up_is_turned_y_up_and_points_only_results(tmp_path):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    from fourd.io.axes import z_up_to_y_up

    anim = _animation(frames=2)
    save(anim, tmp_path / "z.abc", up="z", scale=100.0)
    _, schema = _open(tmp_path / "z.abc")
    positions, _, _, normals = _sample(schema, 1)
    assert np.abs(positions - z_up_to_y_up(100 * anim.vertices[1])).max() <= 1e-4
    outward = np.einsum("ij,ij->i", normals, positions - positions.mean(axis=0))
    assert (outward > 0).all()
    points = AnimatedMesh(np.zeros((0, 3), int), anim.vertices)
    save(points, tmp_path / "points.abc")
    back = load_result(tmp_path / "points.abc")
    assert len(back.faces) == 0 and np.abs(back.vertices - anim.vertices).max() <= 1e-6


def test_a_foreign_archive_with_quads(tmp_path):
    """An archive fourd did not write: quads are fanned, times are the samples' seconds."""
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    import imath
    from alembic3d import Abc, AbcCoreAbstract, AbcGeom

    archive = Abc.OArchive(str(tmp_path / "quad.abc"))
    index = archive.addTimeSampling(AbcCoreAbstract.TimeSampling(0.5, 1.0))
    mesh = AbcGeom.OPolyMesh(AbcGeom.OXform(archive.getTop(), "group"), "quad", index)
    square = np.array([[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], np.float32)  # clockwise
    for k in range(2):
        mesh.getSchema().set(AbcGeom.OPolyMeshSchemaSample(
            imath.V3fArrayFromBuffer(square + k), imath.IntArrayFromBuffer(np.arange(4, dtype=np.int32)),
            imath.IntArrayFromBuffer(np.array([4], np.int32))))
    del mesh, archive
    back = read_abc(tmp_path / "quad.abc")
    assert isinstance(back, AnimatedMesh) and back.times.tolist() == [1.0, 1.5]
    assert back.faces.tolist() == [[2, 1, 0], [3, 2, 0]]
    normal = np.cross(*(back.vertices[0][back.faces[0][1:]] - back.vertices[0][back.faces[0][0]]))
    assert normal[2] > 0  # seen from +z the square was clockwise: its front faces +z


def test_unreadable_archives(tmp_path):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    (tmp_path / "junk.abc").write_bytes(b"not an archive")
    with pytest.raises(InputError, match=r"junk\.abc: is not a readable Alembic archive"):
        load_result(tmp_path / "junk.abc")
    with pytest.raises(InputError, match=r"missing\.abc: does not exist"):
        load_result(tmp_path / "missing.abc")
    from alembic3d import Abc

    empty = Abc.OArchive(str(tmp_path / "empty.abc"))
    del empty
    with pytest.raises(InputError, match=r"empty\.abc: holds no polygon mesh"):
        load_result(tmp_path / "empty.abc")


def test_an_interrupted_write_leaves_nothing(tmp_path, monkeypatch):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    import fourd.io.abc as abc

    def explode(*args, **kwargs):
        raise KeyboardInterrupt("interrupted")

    monkeypatch.setattr(abc, "vertex_normals", explode)
    with pytest.raises(KeyboardInterrupt):
        save(_animation(frames=2), tmp_path / "walk.abc")
    assert list(tmp_path.iterdir()) == []


def test_missing_alembic3d_says_what_to_install(tmp_path, monkeypatch):
    real_import = builtins.__import__

    def no_alembic(name, *args, **kwargs):
        if name in ("alembic3d", "imath") or name.startswith("alembic3d."):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_alembic)
    message = r"walk\.abc: writing \.abc needs the alembic3d package: pip install 'fourd\[abc\]'"
    with pytest.raises(InputError, match=message):
        save(_animation(frames=2), tmp_path / "walk.abc")
    with pytest.raises(InputError, match=message):
        check_output(tmp_path / "walk.abc")
    (tmp_path / "other.abc").write_bytes(b"x")
    with pytest.raises(InputError, match=r"reading \.abc needs the alembic3d package"):
        load_result(tmp_path / "other.abc")
    assert [p.name for p in tmp_path.iterdir()] == ["other.abc"]
