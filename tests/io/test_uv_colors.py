"""UVs, vertex colours and observed flags in every output format that holds them, read back
with an independent reader (pygltflib, pxr, alembic3d) or fourd's own (npz, folders)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from gltf_decode import check_structure, decode_animation

from fourd.animation import AnimatedMesh
from fourd.io.colorspace import srgb_to_linear
from fourd.io.meshfiles import read_obj
from fourd.io.results import load_result, save


def _textured(frames=3) -> AnimatedMesh:
    """A sphere that swells, with a UV layout cut in two islands (a seam) and colours that
    change per frame; vertex 3 filled in at frame 1."""
    sphere = trimesh.creation.icosphere(subdivisions=1)
    vertices, faces = sphere.vertices, sphere.faces
    planar = vertices[:, :2] * 0.2 + 0.25  # in [0.05, 0.45]
    uv = planar[faces]
    back = vertices[faces].mean(axis=1)[:, 2] > 0
    uv[back, :, 0] += 0.5  # the back faces: a second island, so the equator is a seam
    rng = np.random.default_rng(3)
    colors = rng.random((frames, len(vertices), 3))
    observed = np.ones((frames, len(vertices)), bool)
    observed[1, 3] = False
    return AnimatedMesh(
        faces,
        np.stack([vertices * (1 + 0.1 * t) + [0.05 * t, 0, 0] for t in range(frames)]),
        observed=observed,
        uv=uv,
        colors=colors,
    )


def test_animated_mesh_checks_uv_and_colors():
    anim = _textured()
    with pytest.raises(ValueError, match=r"uv must .* \[80, 3, 2\]"):
        AnimatedMesh(anim.faces, anim.vertices, uv=anim.uv[:, :2])
    with pytest.raises(ValueError, match=r"colors must .* \[3, 42, 3\]"):
        AnimatedMesh(anim.faces, anim.vertices, colors=anim.colors[0])
    two = anim.select(0, 2)
    assert two.uv is anim.uv and np.array_equal(two.colors, anim.colors[:2])


@pytest.mark.parametrize("encoding", ["quantized", "float"])
def test_glb_texcoords_colors_and_observed(tmp_path, encoding):
    import pygltflib

    anim = _textured()
    save(anim, tmp_path / "t.glb", glb_encoding=encoding)
    gltf = pygltflib.GLTF2.load(tmp_path / "t.glb")
    check_structure(gltf, gltf.binary_blob())
    decoded = decode_animation(gltf, gltf.binary_blob())
    n = anim.vertex_count
    positions, faces = decoded.positions, decoded.faces
    assert positions.shape[1] > n  # the seam's vertices were duplicated
    # the result's own vertices keep their index; the copies sit where their originals are
    tolerance = 2e-5 * anim.diagonal()
    assert np.abs(positions[:, :n] - anim.vertices).max() <= tolerance
    original = np.empty(len(positions[0]), dtype=int)
    original[faces.ravel()] = anim.faces.ravel()
    assert np.array_equal(original[:n], np.arange(n))
    assert np.abs(positions - anim.vertices[:, original]).max() <= tolerance
    # TEXCOORD_0 per vertex gives every corner its own UV back, v flipped (glTF's v is down)
    texcoord = decoded.attributes["TEXCOORD_0"]
    corners = texcoord[faces]
    assert np.allclose(corners[..., 0], anim.uv[..., 0], atol=1e-6)
    assert np.allclose(1.0 - corners[..., 1], anim.uv[..., 1], atol=1e-6)
    # COLOR_0: the mean linear colour over the frames where the vertex was observed
    weights = anim.observed.astype(float)
    expected = np.einsum("tn,tnc->nc", weights, srgb_to_linear(anim.colors)) / weights.sum(0)[:, None]
    color = decoded.attributes["COLOR_0"]
    assert color.shape == (len(positions[0]), 4) and np.allclose(color[:, 3], 1.0)
    assert np.abs(color[:, :3] - expected[original]).max() <= 1e-4
    assert gltf.accessors[gltf.meshes[0].primitives[0].attributes.COLOR_0].normalized
    assert gltf.materials[0].pbrMetallicRoughness.baseColorFactor == [1.0, 1.0, 1.0, 1.0]
    assert np.array_equal(decoded.attributes["_OBSERVED"], anim.observed[0, original].astype(float))


def test_usd_st_display_color_and_observed_primvars(tmp_path):
    pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    from pxr import Usd, UsdGeom

    anim = _textured()
    save(anim, tmp_path / "t.usda")
    stage = Usd.Stage.Open(str(tmp_path / "t.usda"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Root/Mesh"))
    primvars = UsdGeom.PrimvarsAPI(mesh)
    st = primvars.GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying and st.IsIndexed()
    assert str(st.GetTypeName()) == "texCoord2f[]"
    corners = np.array(st.ComputeFlattened()).reshape(-1, 3, 2)
    assert np.abs(corners - anim.uv).max() <= 1e-6
    display = mesh.GetDisplayColorPrimvar()
    assert display.GetInterpolation() == UsdGeom.Tokens.vertex
    observed = primvars.GetPrimvar("observed")
    assert observed.GetInterpolation() == UsdGeom.Tokens.vertex
    for k, t in enumerate(anim.times):
        code = Usd.TimeCode(t)
        colors = np.array(display.Get(code))
        assert np.abs(colors - srgb_to_linear(anim.colors[k])).max() <= 1e-6
        assert np.array_equal(np.array(observed.Get(code)), anim.observed[k].astype(float))


def test_abc_uvs_and_cd_back_through_alembic(tmp_path):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    from alembic3d import Abc, AbcGeom

    anim = _textured()
    save(anim, tmp_path / "t.abc")
    archive = Abc.IArchive(str(tmp_path / "t.abc"))
    mesh = AbcGeom.IPolyMesh(archive.getTop().getChild(0), "fourdShape")
    schema = mesh.getSchema()
    uvs = schema.getUVsParam()
    assert uvs.valid() and uvs.getScope() == AbcGeom.GeometryScope.kFacevaryingScope
    cd = AbcGeom.IC3fGeomParam(schema.getArbGeomParams(), "Cd")
    assert cd.getScope() == AbcGeom.GeometryScope.kVertexScope and cd.getNumSamples() == 3
    back = load_result(tmp_path / "t.abc")  # fourd's reader undoes the clockwise corners
    assert np.array_equal(back.faces, anim.faces)
    assert np.abs(back.uv - anim.uv).max() <= 1e-6
    assert np.abs(back.colors - anim.colors).max() <= 1e-5
    assert np.array_equal(back.observed, anim.observed)


def test_obj_folder_vt_and_vertex_colors_per_frame(tmp_path):
    anim = _textured()
    save(anim, tmp_path / "frames/")
    first = read_obj(tmp_path / "frames" / "frame_0000.obj")
    assert "vt " in (tmp_path / "frames" / "frame_0000.obj").read_text()
    assert np.abs(first.uv - anim.uv).max() <= 1e-8
    back = load_result(tmp_path / "frames")
    assert np.abs(back.uv - anim.uv).max() <= 1e-8
    assert np.abs(back.colors - anim.colors).max() <= 1e-5
    assert np.array_equal(back.observed, anim.observed)


def test_ply_folder_vertex_colors_and_npz(tmp_path):
    anim = _textured()
    save(anim, tmp_path / "plys/", mesh_format="ply")
    back = load_result(tmp_path / "plys")
    assert back.uv is None  # PLY holds no per-corner UVs
    assert np.abs(back.colors - anim.colors).max() <= 0.5 / 255 + 1e-9
    save(anim, tmp_path / "t.npz")
    with np.load(tmp_path / "t.npz") as data:
        assert data["colors"].dtype == np.uint8 and data["uv"].shape == anim.uv.shape
    back = load_result(tmp_path / "t.npz")
    assert np.abs(back.uv - anim.uv).max() <= 1e-7
    assert np.abs(back.colors - anim.colors).max() <= 0.5 / 255 + 1e-9


def test_pc2_topology_obj_carries_the_uvs(tmp_path):
    anim = _textured()
    save(anim, tmp_path / "t.pc2")
    topology = read_obj(tmp_path / "t.obj")
    assert np.array_equal(topology.faces, anim.faces)
    assert np.abs(topology.uv - anim.uv).max() <= 1e-8


def test_scale_and_up_keep_uv_and_colors(tmp_path):
    anim = _textured()
    save(anim, tmp_path / "s.npz", scale=2.0)
    back = load_result(tmp_path / "s.npz")
    assert np.abs(back.vertices - 2 * anim.vertices).max() <= 1e-5
    assert back.uv is not None and back.colors is not None


@pytest.mark.parametrize("encoding", ["quantized", "float"])
def test_a_glb_with_seams_reads_back_as_the_result_it_was(tmp_path, encoding):
    """The writer splits vertices on UV seams; the reader merges them back (one connectivity,
    the result's vertex count, UVs per corner, colours)."""
    from fourd.io.results import load_result

    anim = _textured()
    save(anim, tmp_path / "t.glb", glb_encoding=encoding)
    back = load_result(tmp_path / "t.glb")
    assert back.vertex_count == anim.vertex_count and np.array_equal(back.faces, anim.faces)
    assert np.abs(back.vertices - anim.vertices).max() <= 2.0 * anim.diagonal() / 32767
    assert np.allclose(back.uv, anim.uv, atol=1e-6)
    assert back.colors is not None and back.colors.shape == anim.colors.shape
