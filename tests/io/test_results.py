"""Result writers, each checked with an independent reader; atomicity; load_result."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest
import trimesh
from gltf_decode import accessor, check_structure, decode_animation

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.geometry.normals import vertex_normals
from fourd.io import meshfolder
from fourd.io.atomic import atomic_path
from fourd.io.pc2 import read_pc2
from fourd.io.results import load_result, output_kind, save


def _animation(frames=5, subdivisions=2, seed=0) -> AnimatedMesh:
    """A sphere that swells, shears and travels: every frame distinct."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    base = sphere.vertices
    rng = np.random.default_rng(seed)
    vertices = []
    for t in range(frames):
        shear = np.eye(3) + 0.1 * t * np.array([[0, 1, 0], [0, 0, 0], [0, 0, 0]])
        vertices.append(
            (base * (1 + 0.05 * t)) @ shear.T + [0.2 * t, 0, 0] + 0.01 * rng.normal(size=base.shape)
        )
    observed = np.ones((frames, len(base)), bool)
    observed[1, :10] = False
    return AnimatedMesh(
        sphere.faces,
        np.stack(vertices),
        times=0.5 * np.arange(frames) + 1.0,
        observed=observed,
        rest=base,
    )


def _sequence() -> MeshSequence:
    a = trimesh.creation.icosphere(subdivisions=1)
    b = trimesh.creation.box()
    c = trimesh.creation.cylinder(radius=0.5, height=1.0, sections=12)
    return MeshSequence(
        ((a.vertices, a.faces), (b.vertices, b.faces), (c.vertices, c.faces)), times=[0.0, 0.5, 2.0]
    )


# ------------------------------------------------------------------------------------ npz


def test_npz_contract_keys(tmp_path):
    anim = _animation()
    save(anim, tmp_path / "walk.npz")
    with np.load(tmp_path / "walk.npz") as data:
        assert (
            data["vertices"].dtype == np.float32 and data["vertices"].shape == anim.vertices.shape
        )
        assert data["faces"].dtype == np.int32 and np.array_equal(data["faces"], anim.faces)
        assert np.array_equal(data["times"], anim.times)
        assert data["observed"].dtype == bool and np.array_equal(data["observed"], anim.observed)
        assert np.abs(data["rest"] - anim.rest).max() <= 1e-6
        assert np.abs(data["vertices"] - anim.vertices).max() <= 1e-6
    back = load_result(tmp_path / "walk.npz")
    assert isinstance(back, AnimatedMesh)
    assert np.array_equal(back.observed, anim.observed)
    assert np.abs(back.vertices - anim.vertices).max() <= 1e-6


def test_npz_mesh_sequence(tmp_path):
    seq = _sequence()
    save(seq, tmp_path / "seq.npz")
    with np.load(tmp_path / "seq.npz") as data:
        assert str(data["kind"]) == "meshes"
        assert np.array_equal(data["times"], seq.times)
        for t, (v, f) in enumerate(seq.meshes):
            assert np.abs(data[f"vertices_{t}"] - v).max() <= 1e-6
            assert np.array_equal(data[f"faces_{t}"], f)
    back = load_result(tmp_path / "seq.npz")
    assert isinstance(back, MeshSequence) and len(back) == 3
    assert np.array_equal(back.meshes[1][1], seq.meshes[1][1])


# ------------------------------------------------------------------------------------ glb


def _accessor(gltf, blob, index):
    return accessor(gltf, blob, index)


@pytest.mark.parametrize("encoding", ["quantized", "float"])
def test_glb_morph_targets_and_animation(tmp_path, encoding):
    import pygltflib

    anim = _animation(frames=6)
    save(anim, tmp_path / "walk.glb", glb_encoding=encoding)
    gltf = pygltflib.GLTF2.load(tmp_path / "walk.glb")
    blob = gltf.binary_blob()
    assert gltf.asset.version == "2.0"
    primitive = gltf.meshes[0].primitives[0]
    assert len(primitive.targets) == anim.frame_count - 1
    assert len(gltf.meshes[0].weights) == anim.frame_count - 1
    count = anim.vertex_count
    assert gltf.accessors[primitive.attributes.POSITION].count == count
    assert gltf.accessors[primitive.attributes.NORMAL].count == count
    for target in primitive.targets:  # loaded targets are plain dicts
        assert gltf.accessors[target["POSITION"]].count == count
        assert gltf.accessors[target["NORMAL"]].count == count
    check_structure(gltf, blob)
    decoded = decode_animation(gltf, blob)
    assert np.array_equal(decoded.faces, anim.faces)
    # quantized: int16 over the animation's extent, a step of about diagonal / 65,000
    tolerance = 1e-5 if encoding == "float" else 2e-5 * anim.diagonal()
    assert np.abs(decoded.positions - anim.vertices).max() <= tolerance
    normals = vertex_normals(anim.vertices, anim.faces)
    cosine = np.einsum("tij,tij->ti", decoded.normals, normals)
    assert cosine.min() >= np.cos(np.radians(1.0))
    if encoding == "quantized":
        assert gltf.extensionsRequired == ["KHR_mesh_quantization"]
        target = gltf.accessors[primitive.targets[0]["POSITION"]]
        assert target.componentType == 5122 and target.normalized
        assert gltf.bufferViews[target.bufferView].byteStride == 8  # 4-byte aligned rows
    else:
        assert not gltf.extensionsRequired and not gltf.nodes[0].scale
    for index in [primitive.attributes.POSITION] + [t["POSITION"] for t in primitive.targets]:
        accessor_ = gltf.accessors[index]
        raw = _raw(gltf, blob, index)  # bounds are of the stored values, normalized or not
        assert np.allclose(accessor_.min, raw.min(axis=0)) and np.allclose(
            accessor_.max, raw.max(axis=0)
        )
    sampler = gltf.animations[0].samplers[0]
    channel = gltf.animations[0].channels[0]
    assert channel.target.path == "weights" and channel.target.node == 0
    assert sampler.interpolation == "LINEAR"
    times = _accessor(gltf, blob, sampler.input)
    assert np.allclose(times, anim.times)
    assert gltf.accessors[sampler.input].min == [pytest.approx(anim.times[0])]
    assert gltf.accessors[sampler.input].max == [pytest.approx(anim.times[-1])]
    weights = _accessor(gltf, blob, sampler.output).reshape(anim.frame_count, anim.frame_count - 1)
    assert np.array_equal(weights[0], np.zeros(anim.frame_count - 1))
    assert np.array_equal(weights[1:], np.eye(anim.frame_count - 1))
    normals = _accessor(gltf, blob, primitive.attributes.NORMAL)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    observed = decoded.attributes["_OBSERVED"]
    assert np.array_equal(observed, anim.observed[0].astype(float))


def _raw(gltf, blob, index):
    """The stored values of an accessor, integers as integers."""
    accessor_ = gltf.accessors[index]
    normalized, accessor_.normalized = accessor_.normalized, False
    try:
        return _accessor(gltf, blob, index)
    finally:
        accessor_.normalized = normalized


def test_glb_loads_in_trimesh(tmp_path):
    anim = _animation(frames=3)
    save(anim, tmp_path / "walk.glb", interpolation="STEP")
    scene = trimesh.load(tmp_path / "walk.glb")
    geometry = list(scene.geometry.values())
    assert len(geometry) == 1 and len(geometry[0].faces) == len(anim.faces)


def test_glb_mesh_sequence_one_node_per_frame(tmp_path):
    import pygltflib

    seq = _sequence()
    save(seq, tmp_path / "seq.glb")
    gltf = pygltflib.GLTF2.load(tmp_path / "seq.glb")
    blob = gltf.binary_blob()
    check_structure(gltf, blob)
    assert len(gltf.nodes) == 3 and len(gltf.meshes) == 3
    animation = gltf.animations[0]
    assert {c.target.path for c in animation.channels} == {"scale"}
    for k, channel in enumerate(animation.channels):
        sampler = animation.samplers[channel.sampler]
        assert np.allclose(_accessor(gltf, blob, sampler.input), seq.times)
        scales = _accessor(gltf, blob, sampler.output)
        assert np.array_equal(scales[:, 0] > 0, np.arange(3) == k)
        mesh = gltf.meshes[gltf.nodes[channel.target.node].mesh]
        position = _accessor(gltf, blob, mesh.primitives[0].attributes.POSITION)
        assert np.abs(position - seq.meshes[k][0]).max() <= 1e-6


def test_glb_point_animation_without_faces(tmp_path):
    import pygltflib

    rng = np.random.default_rng(4)
    anim = AnimatedMesh(np.zeros((0, 3), int), rng.normal(size=(3, 50, 3)))
    save(anim, tmp_path / "points.glb")
    gltf = pygltflib.GLTF2.load(tmp_path / "points.glb")
    check_structure(gltf, gltf.binary_blob())
    primitive = gltf.meshes[0].primitives[0]
    assert primitive.mode == 0 and primitive.indices is None
    assert len(primitive.targets) == 2


# ------------------------------------------------------------------------------------ usd


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd"])
def test_usd_time_sampled_points(tmp_path, suffix):
    pxr = pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    from pxr import Usd, UsdGeom

    anim = _animation(frames=4)
    save(anim, tmp_path / f"walk{suffix}", fps=24, time_unit="frames")
    assert pxr is not None
    stage = Usd.Stage.Open(str(tmp_path / f"walk{suffix}"))
    assert stage.GetStartTimeCode() == anim.times[0] and stage.GetEndTimeCode() == anim.times[-1]
    assert stage.GetTimeCodesPerSecond() == 24
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Root/Mesh"))
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(anim.faces)
    assert np.array_equal(
        np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3), anim.faces
    )
    points = mesh.GetPointsAttr()
    assert points.GetTimeSamples() == pytest.approx(list(anim.times))
    for k, t in enumerate(anim.times):
        assert np.abs(np.array(points.Get(Usd.TimeCode(t))) - anim.vertices[k]).max() <= 1e-5


def test_usd_missing_pxr_says_what_to_install(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_pxr(name, *args, **kwargs):
        if name == "pxr" or name.startswith("pxr."):
            raise ImportError("No module named 'pxr'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pxr)
    with pytest.raises(InputError, match=r'pip install "fourd\[usd\]"') as info:
        save(_animation(frames=2), tmp_path / "walk.usda")
    assert "walk.usda" in str(info.value)
    assert not (tmp_path / "walk.usda").exists()


# ------------------------------------------------------------------------------------ pc2


def test_pc2_bytes_and_topology(tmp_path):
    anim = _animation(frames=4)
    anim = AnimatedMesh(anim.faces, anim.vertices, times=[3.0, 4.0, 5.0, 6.0])
    save(anim, tmp_path / "walk.pc2")
    data = (tmp_path / "walk.pc2").read_bytes()
    assert data[:12] == b"POINTCACHE2\0"
    version, points, start, rate, samples = struct.unpack_from("<iiffi", data, 12)
    assert (version, points, start, rate, samples) == (1, anim.vertex_count, 3.0, 1.0, 4)
    assert len(data) == 32 + 4 * 3 * points * samples
    positions = np.frombuffer(data, "<f4", offset=32).reshape(samples, points, 3)
    assert np.abs(positions - anim.vertices).max() <= 1e-5
    topology = trimesh.load(tmp_path / "walk.obj", process=False)
    assert np.array_equal(topology.faces, anim.faces)
    assert np.abs(topology.vertices - anim.vertices[0]).max() <= 1e-6
    assert np.abs(read_pc2(tmp_path / "walk.pc2").vertices - anim.vertices).max() <= 1e-5


def test_pc2_of_a_mesh_sequence_shows_each_frame_its_own_mesh(tmp_path):
    """Changing connectivity (a shape that splits) is baked into one: frame t's own mesh is
    in place, every other frame's mesh collapsed to a point, so only frame t's area shows."""
    meshes = _sequence()
    save(meshes, tmp_path / "walk.pc2")
    cache = read_pc2(tmp_path / "walk.pc2").vertices
    faces = trimesh.load(tmp_path / "walk.obj", process=False).faces
    assert cache.shape == (3, sum(len(v) for v, _ in meshes.meshes), 3)
    for t, (vertices, own) in enumerate(meshes.meshes):
        mesh = trimesh.Trimesh(cache[t], faces, process=False)
        assert mesh.area == pytest.approx(trimesh.Trimesh(vertices, own).area, rel=1e-5)


# ---------------------------------------------------------------------------- per frame


@pytest.mark.parametrize("mesh_format", ["obj", "ply"])
def test_folder_of_meshes(tmp_path, mesh_format):
    anim = _animation(frames=3)
    save(anim, str(tmp_path / "out") + "/", mesh_format=mesh_format)
    files = sorted((tmp_path / "out").glob(f"frame_*.{mesh_format}"))
    assert [f.name for f in files] == [f"frame_{k:04d}.{mesh_format}" for k in range(3)]
    for k, file in enumerate(files):
        mesh = trimesh.load(file, process=False)
        assert np.array_equal(mesh.faces, anim.faces)
        assert np.abs(mesh.vertices - anim.vertices[k]).max() <= 1e-6
    back = load_result(tmp_path / "out")
    assert isinstance(back, AnimatedMesh)
    assert np.allclose(back.times, anim.times)
    assert np.abs(back.vertices - anim.vertices).max() <= 1e-6
    assert np.array_equal(back.observed, anim.observed) and not back.observed[1, :10].any()


def test_folder_observed_flags_are_checked(tmp_path):
    save(_animation(frames=3), tmp_path / "out")
    np.save(tmp_path / "out" / "observed.npy", np.ones((2, 5), bool))
    with pytest.raises(InputError, match=r"observed\.npy: .*shape \[3, 162\]"):
        load_result(tmp_path / "out")
    (tmp_path / "out" / "observed.npy").unlink()
    assert load_result(tmp_path / "out").observed.all()


def test_folder_of_a_mesh_sequence_and_existing_folder(tmp_path):
    seq = _sequence()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "stale.obj").write_text("v 0 0 0\n")
    save(seq, tmp_path / "out")
    assert not (tmp_path / "out" / "stale.obj").exists()
    back = load_result(tmp_path / "out")
    assert isinstance(back, MeshSequence)
    for (v, f), (v2, f2) in zip(seq.meshes, back.meshes, strict=True):
        assert np.array_equal(f, f2) and np.abs(v - v2).max() <= 1e-6
    save(seq, tmp_path / "noext")
    assert (tmp_path / "noext" / "frame_0002.obj").is_file()


# ------------------------------------------------------------------------- reading back

_READ_BACK = [
    (".npz", True, True),
    (".glb", False, False),
    (".usda", False, False),
    (".usdc", False, False),
    (".pc2", False, False),
    (".abc", True, False),
    ("/", True, False),
]


@pytest.mark.parametrize(("suffix", "keeps_observed", "keeps_rest"), _READ_BACK)
def test_every_format_reads_back_as_written(tmp_path, suffix, keeps_observed, keeps_rest):
    """load_result reads what save wrote, in every format: the same faces, vertices within
    float32 rounding, the times (.pc2: as frame numbers), observed where the format holds it."""
    if suffix.startswith(".usd"):
        pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    if suffix == ".abc":
        pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    anim = _animation(frames=4)
    target = str(tmp_path / "walk") + suffix
    save(anim, target)
    back = load_result(target)
    assert isinstance(back, AnimatedMesh)
    assert np.array_equal(back.faces, anim.faces)
    # float32 rounding; .glb quantizes to 16 bits of the box by default (KHR_mesh_quantization)
    tolerance = 2.0 * anim.diagonal() / 32767 if suffix == ".glb" else 1e-5
    assert np.abs(back.vertices - anim.vertices).max() <= tolerance
    if suffix == ".pc2":  # a point cache counts frames: the times come back as frame numbers
        rate = 1.0 / float(np.median(np.diff(anim.times)))
        assert np.allclose(back.times, anim.times * rate, atol=1e-4)
    else:
        assert np.allclose(back.times, anim.times, atol=1e-6)
    if keeps_observed:
        assert np.array_equal(back.observed, anim.observed)
    else:
        assert back.observed.all()
    assert (back.rest is not None) == keeps_rest


@pytest.mark.parametrize("suffix", [".npz", ".glb", ".usda", "/"])
def test_per_frame_meshes_read_back_as_per_frame_meshes(tmp_path, suffix):
    if suffix.startswith(".usd"):
        pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    seq = _sequence()
    target = str(tmp_path / "seq") + suffix
    save(seq, target)
    back = load_result(target)
    assert isinstance(back, MeshSequence) and np.allclose(back.times, seq.times)
    for (v, f), (v2, f2) in zip(seq.meshes, back.meshes, strict=True):
        assert np.array_equal(f, f2) and np.abs(v - v2).max() <= 1e-6


def test_glb_points_and_a_single_frame_read_back(tmp_path):
    rng = np.random.default_rng(4)
    points = AnimatedMesh(np.zeros((0, 3), int), rng.normal(size=(3, 50, 3)))
    save(points, tmp_path / "points.glb")
    back = load_result(tmp_path / "points.glb")
    # 16-bit quantized positions (the default .glb encoding)
    assert back.faces.shape == (0, 3)
    assert np.abs(back.vertices - points.vertices).max() <= 2.0 * points.diagonal() / 32767
    first = _animation(frames=2)
    one = AnimatedMesh(first.faces, first.vertices[:1])
    save(one, tmp_path / "one.glb")
    assert load_result(tmp_path / "one.glb").vertices.shape == one.vertices.shape


def test_reading_back_bad_files_names_them(tmp_path):
    (tmp_path / "junk.glb").write_bytes(b"glTF" + bytes(8))
    with pytest.raises(InputError, match=r"junk\.glb: is not a readable \.glb"):
        load_result(tmp_path / "junk.glb")
    (tmp_path / "text.glb").write_text("hello")
    with pytest.raises(InputError, match=r"text\.glb: not a glTF binary"):
        load_result(tmp_path / "text.glb")
    save(_animation(frames=2), tmp_path / "walk.pc2")
    (tmp_path / "walk.obj").unlink()
    with pytest.raises(InputError, match=r"walk\.pc2: the topology walk\.obj is missing"):
        load_result(tmp_path / "walk.pc2")
    save(_animation(frames=2), tmp_path / "walk.pc2")
    (tmp_path / "walk.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="162 points but walk.obj has 3 vertices"):
        load_result(tmp_path / "walk.pc2")


def test_reading_usd_without_pxr_says_what_to_install(tmp_path, monkeypatch):
    import builtins

    (tmp_path / "walk.usda").write_text("#usda 1.0\n")
    real_import = builtins.__import__

    def no_pxr(name, *args, **kwargs):
        if name == "pxr" or name.startswith("pxr."):
            raise ImportError("No module named 'pxr'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pxr)
    with pytest.raises(InputError, match=r'walk\.usda: reading USD needs usd-core.*"fourd\[usd\]"'):
        load_result(tmp_path / "walk.usda")


def test_every_writable_format_has_a_reader():
    from fourd.io.results import READERS, RESULT_SUFFIXES, USD_SUFFIXES

    kinds = {"usd" if s in USD_SUFFIXES else s[1:] for s in RESULT_SUFFIXES} | {"folder"}
    assert kinds == set(READERS)


# ------------------------------------------------------------------------- bad outputs


def test_output_kinds(tmp_path):
    assert (
        output_kind("a.NPZ") == "npz"
        and output_kind("a.usdc") == "usd"
        and output_kind("a/") == "folder"
    )
    assert output_kind(tmp_path) == "folder" and output_kind(tmp_path / "new") == "folder"


def test_unknown_extension(tmp_path):
    with pytest.raises(InputError, match=r"walk\.fbx.*unknown output format"):
        save(_animation(frames=2), tmp_path / "walk.fbx")


@pytest.mark.parametrize("name", ["walk.npz", "walk.glb", "walk.pc2", "walk_dir/"])
def test_missing_or_unwritable_output_folder(tmp_path, monkeypatch, name):
    with pytest.raises(InputError, match="does not exist"):
        save(_animation(frames=2), str(tmp_path / "missing" / name))
    import fourd.io.atomic as atomic

    monkeypatch.setattr(atomic.os, "access", lambda path, mode: False)
    with pytest.raises(InputError, match="not writable") as info:
        save(_animation(frames=2), str(tmp_path / name))
    assert str(tmp_path) in str(info.value)


@pytest.mark.parametrize("name", ["walk.npz", "walk.glb", "walk.pc2", "walk.usda", "walk_dir"])
def test_interrupted_write_leaves_nothing(tmp_path, monkeypatch, name):
    """Make the lowest-level write fail midway: no file under the target name, no debris."""
    if name.endswith(".usda"):
        pytest.importorskip("pxr")

    def explode(*args, **kwargs):
        raise KeyboardInterrupt("interrupted")

    monkeypatch.setattr(meshfolder, "write_obj", explode)  # folder of meshes
    monkeypatch.setattr(np, "savez", explode)
    monkeypatch.setattr("pygltflib.GLTF2.save_binary", explode)
    monkeypatch.setattr("fourd.io.pc2.open", explode, raising=False)  # the point cache body
    if name.endswith(".usda"):
        from pxr import Sdf

        monkeypatch.setattr(Sdf.Layer, "Save", explode)
    with pytest.raises(KeyboardInterrupt):
        save(_animation(frames=2), tmp_path / name)
    assert not (tmp_path / name).exists()
    assert [p.name for p in tmp_path.iterdir()] == []


def test_atomic_path_keeps_the_old_file_on_failure(tmp_path):
    target = tmp_path / "walk.npz"
    save(_animation(frames=2), target)
    before = target.read_bytes()
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("crash")
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["walk.npz"]


def test_load_result_problems(tmp_path):
    with pytest.raises(InputError, match="nothing.npz"):
        load_result(tmp_path / "nothing.npz")
    np.savez(tmp_path / "other.npz", points=np.ones((3, 3)))
    with pytest.raises(InputError, match="other.npz.*not a fourd result"):
        load_result(tmp_path / "other.npz")
    np.savez(tmp_path / "bad.npz", vertices=np.ones((2, 3, 3)), faces=[[0, 1, 5]])
    with pytest.raises(InputError, match="bad.npz"):
        load_result(tmp_path / "bad.npz")
    (tmp_path / "junk.npz").write_bytes(b"junk")
    with pytest.raises(InputError, match="junk.npz"):
        load_result(tmp_path / "junk.npz")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="empty"):
        load_result(tmp_path / "empty")
    (tmp_path / "walk.xyz3").write_text("x")
    with pytest.raises(InputError, match=r"walk\.xyz3: not a result format"):
        load_result(tmp_path / "walk.xyz3")


def test_check_output_before_computing(tmp_path):
    from fourd.io.results import check_output

    assert check_output(tmp_path / "walk.glb") == "glb"
    assert check_output(str(tmp_path / "frames") + "/") == "folder"
    with pytest.raises(InputError, match=r"walk\.fbx"):
        check_output(tmp_path / "walk.fbx")
    with pytest.raises(InputError, match="does not exist"):
        check_output(tmp_path / "missing" / "walk.npz")
    (tmp_path / "plain").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        check_output(tmp_path / "plain")
    assert not list(tmp_path.glob("walk*"))


def test_check_output_missing_folders_that_can_be_created(tmp_path):
    from fourd.io.results import check_output

    target = tmp_path / "new" / "deeper" / "walk.npz"
    assert check_output(target, create_parents=True) == "npz"
    assert check_output(str(tmp_path / "new" / "frames") + "/", create_parents=True) == "folder"
    assert list(tmp_path.iterdir()) == []  # nothing created, no probe left behind
    (tmp_path / "plain").write_text("x")
    for path in (tmp_path / "plain" / "walk.npz", tmp_path / "plain" / "sub" / "walk.npz"):
        with pytest.raises(InputError, match=r"plain is a file, not a folder") as info:
            check_output(path, create_parents=True)
        assert str(info.value).startswith(str(path))


def test_check_output_tries_a_file_where_the_permission_bits_say_yes(tmp_path, monkeypatch):
    """Root passes every permission test, but /proc (or a read-only mount) takes no file: the
    check makes and removes one, and names the folder and the reason."""
    import fourd.io.results as results
    from fourd.io.results import check_output

    def refuse(*args, **kwargs):
        raise OSError(30, "Read-only file system")

    monkeypatch.setattr(results.tempfile, "mkstemp", refuse)
    monkeypatch.setattr(results.tempfile, "mkdtemp", refuse)
    for path in (tmp_path / "walk.npz", tmp_path / "new" / "walk.npz"):
        with pytest.raises(InputError, match=rf"cannot write in the output folder {tmp_path} \(Read-only"):
            check_output(path, create_parents=True)
    monkeypatch.undo()
    if os.path.isdir("/proc") and os.access("/proc", os.W_OK):
        with pytest.raises(InputError, match=r"/proc/walk\.npz: cannot write in the output folder /proc"):
            check_output("/proc/walk.npz")


def test_one_connectivity_kinds_are_output_kinds():
    from fourd.io.results import ONE_CONNECTIVITY_KINDS

    assert ONE_CONNECTIVITY_KINDS == ("pc2",)
    assert all(output_kind(f"walk.{kind}") == kind for kind in ONE_CONNECTIVITY_KINDS)


# ------------------------------------------------------- time base, up axis and scale


def _frames_anim(frames=3) -> AnimatedMesh:
    """A small animation whose times are frame numbers (0, 1, 2, ...)."""
    anim = _animation(frames=frames, subdivisions=1)
    return AnimatedMesh(anim.faces, anim.vertices, observed=anim.observed)


def _glb_times_and_base(path):
    import pygltflib

    gltf = pygltflib.GLTF2.load(path)
    blob = gltf.binary_blob()
    times = _accessor(gltf, blob, gltf.animations[0].samplers[0].input)
    decoded = decode_animation(gltf, blob)
    return times, decoded.positions[0], decoded.normals[0]


def test_glb_keyframes_are_seconds_from_the_time_base(tmp_path):
    anim = _frames_anim()
    save(anim, tmp_path / "default.glb")  # frame numbers at 30 fps
    times, _, _ = _glb_times_and_base(tmp_path / "default.glb")
    assert np.allclose(times, [0, 1 / 30, 2 / 30])
    save(anim, tmp_path / "film.glb", fps=24)
    assert np.allclose(_glb_times_and_base(tmp_path / "film.glb")[0], [0, 1 / 24, 2 / 24])
    stamped = AnimatedMesh(anim.faces, anim.vertices, times=[10.0, 10.04, 10.08])
    save(stamped, tmp_path / "stamped.glb", fps=50)  # seconds stay seconds whatever the rate
    assert np.allclose(_glb_times_and_base(tmp_path / "stamped.glb")[0], [10.0, 10.04, 10.08])
    save(anim, tmp_path / "seconds.glb", time_unit="seconds")
    assert np.allclose(_glb_times_and_base(tmp_path / "seconds.glb")[0], [0, 1, 2])


def test_glb_z_up_data_is_turned_y_up_and_scaled(tmp_path):
    from fourd.io.axes import z_up_to_y_up

    anim = _frames_anim()
    save(anim, tmp_path / "z.glb", up="z", scale=2.0)
    _, base, normals = _glb_times_and_base(tmp_path / "z.glb")
    expected = z_up_to_y_up(2.0 * anim.vertices[0])
    assert np.abs(base - expected).max() <= 1e-5
    # the normals turn with the points: they still point out of the (centred) sphere
    outward = np.einsum("ij,ij->i", normals, expected - expected.mean(axis=0))
    assert (outward > 0).mean() > 0.95


def test_usd_stage_metadata_time_codes_and_normals(tmp_path):
    pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    from pxr import Usd, UsdGeom

    anim = _frames_anim(frames=4)
    save(anim, tmp_path / "walk.usda", fps=24, up="z", scale=0.5)
    stage = Usd.Stage.Open(str(tmp_path / "walk.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 24 and stage.GetFramesPerSecond() == 24
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 3.0)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Root/Mesh"))
    points = mesh.GetPointsAttr()
    normals = mesh.GetNormalsAttr()
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    assert points.GetTimeSamples() == [0.0, 1.0, 2.0, 3.0] == normals.GetTimeSamples()
    for k in range(4):
        # Z up is declared, not applied: the points are the data's, scaled
        assert np.abs(np.array(points.Get(k)) - 0.5 * anim.vertices[k]).max() <= 1e-6
        n = np.array(normals.Get(k))
        assert n.shape == (anim.vertex_count, 3)
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)


def test_usd_time_codes_of_seconds_are_frames_at_the_measured_rate(tmp_path):
    pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    from pxr import Usd, UsdGeom

    anim = _frames_anim()
    stamped = AnimatedMesh(anim.faces, anim.vertices, times=[2.0, 2.04, 2.08])
    save(stamped, tmp_path / "walk.usdc")
    stage = Usd.Stage.Open(str(tmp_path / "walk.usdc"))
    assert stage.GetTimeCodesPerSecond() == 25 and UsdGeom.GetStageUpAxis(stage) == "Y"
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Root/Mesh")).GetPointsAttr()
    assert points.GetTimeSamples() == [50.0, 51.0, 52.0]


def test_pc2_counts_frames_of_the_time_base(tmp_path):
    anim = _frames_anim()
    stamped = AnimatedMesh(anim.faces, anim.vertices, times=[2.0, 2.04, 2.08])
    save(stamped, tmp_path / "walk.pc2")
    cache = read_pc2(tmp_path / "walk.pc2")
    assert (cache.start, cache.rate) == (50.0, pytest.approx(1.0))
    save(stamped, tmp_path / "walk.pc2", fps=100, scale=3.0, up="z")  # up: .pc2 has none
    cache = read_pc2(tmp_path / "walk.pc2")
    assert (cache.start, cache.rate) == (200.0, pytest.approx(4.0))
    assert np.abs(cache.vertices - 3.0 * anim.vertices).max() <= 1e-5


def test_scale_reaches_npz_and_folders_and_bad_options_write_nothing(tmp_path):
    anim = _frames_anim(frames=2)
    save(anim, tmp_path / "walk.npz", scale=10.0, up="z")
    assert np.abs(load_result(tmp_path / "walk.npz").vertices - 10 * anim.vertices).max() <= 1e-4
    save(anim, tmp_path / "frames", scale=0.1)
    assert np.abs(load_result(tmp_path / "frames").vertices - 0.1 * anim.vertices).max() <= 1e-6
    for options, words in (
        ({"scale": 0}, "scale must be"),
        ({"up": "x"}, "'y' or 'z'"),
        ({"fps": -1}, "fps must be"),
        ({"time_unit": "hours"}, "'frames' or 'seconds'"),
    ):
        for name in ("bad.glb", "bad.pc2", "bad.npz"):
            with pytest.raises(InputError, match=words):
                save(anim, tmp_path / name, **options)
    assert not list(tmp_path.glob("bad*"))
