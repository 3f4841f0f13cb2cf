import base64
import json
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.sequence import PointCloudSequence
from fourd.viz import viewer


def deforming_sphere(frames=4, subdivisions=2):
    s = trimesh.creation.icosphere(subdivisions)
    vertices = []
    for t in range(frames):
        v = s.vertices.copy()
        v[:, 1] *= 1 + 0.3 * t
        v[:, 0] += 0.2 * t
        vertices.append(v)
    observed = np.ones((frames, len(s.vertices)), bool)
    observed[:, s.vertices[:, 1] > 0.6] = False
    return AnimatedMesh(s.faces, np.stack(vertices), observed=observed)


def page_data(outdir: Path) -> dict:
    return viewer.read_viewer_data(outdir / "index.html")


def decode(b64, dtype, shape):
    return np.frombuffer(base64.b64decode(b64), dtype=dtype).reshape(shape)


def test_static_folder_is_small_and_licensed():
    static = Path(viewer.__file__).parent / "static"
    total = sum(p.stat().st_size for p in static.rglob("*") if p.is_file())
    assert total < 2_000_000
    assert "MIT" in (static / "three.LICENSE").read_text()


def test_write_viewer_animated_mesh(tmp_path):
    anim = deforming_sphere()
    truth = AnimatedMesh(anim.faces, anim.vertices * 1.02)
    scans = PointCloudSequence.from_arrays([v[::3] for v in anim.vertices])
    index = viewer.write_viewer(
        anim,
        tmp_path / "view",
        truth=truth,
        scans=scans,
        metrics={"chamfer": np.float64(0.01), "nan": float("nan")},
        title="a <b>",
    )
    out = tmp_path / "view"
    assert index == out / "index.html"
    for name in (
        "index.html",
        "viewer.js",
        "viewer.css",
        "three.fourd.min.js",
        "metrics.json",
    ):
        assert (out / name).is_file(), name
    data = page_data(out)
    assert data["kind"] == "animated" and data["frameCount"] == 4
    positions = decode(data["positions"], "<f4", anim.vertices.shape)
    assert np.allclose(positions, anim.vertices, atol=1e-6)
    assert np.array_equal(decode(data["faces"], "<u4", anim.faces.shape), anim.faces)
    assert np.array_equal(
        decode(data["observed"], "u1", anim.observed.shape).astype(bool), anim.observed
    )
    errors = decode(data["errors"], "<f4", anim.observed.shape)
    bound = 0.02 * np.linalg.norm(
        anim.vertices, axis=2
    )  # a vertex is this far from its scaled self
    assert data["hasErrors"] and np.all(errors <= bound + 1e-6) and errors.mean() > 0
    assert data["truthDiagonal"] == pytest.approx(truth.diagonal())  # the legend's "% of"
    assert len(data["points"]) == 4
    assert json.loads((out / "metrics.json").read_text()) == {"chamfer": 0.01, "nan": None}

    page = index.read_text()
    # self-contained: scripts inline, nothing fetched from a network or a sibling file
    assert not re.search(r"""(src|href)\s*=\s*["'](https?:)?//""", page)
    assert not re.search(r"""<script[^>]+src=""", page)
    assert "window.FOURD_DATA" in page and "fourdSetFrame" in page
    assert "a &lt;b&gt;" in page
    assert page.count("<script>") == 3 and page.count("</script>") == 3


def test_write_viewer_embeds_the_glb_when_the_writer_exists(tmp_path):
    pytest.importorskip("fourd.io.results")
    anim = deforming_sphere(frames=3)
    viewer.write_viewer(anim, tmp_path / "v")
    data = page_data(tmp_path / "v")
    glb = base64.b64decode(data["glb"])
    assert glb[:4] == b"glTF" and glb == (tmp_path / "v" / "result.glb").read_bytes()


def test_the_viewers_glb_keeps_the_results_vertices_when_it_has_uvs(tmp_path):
    import dataclasses

    import pygltflib

    anim = deforming_sphere(frames=3)
    uv = np.random.default_rng(0).random((len(anim.faces), 3, 2))  # every corner its own UV
    viewer.write_viewer(dataclasses.replace(anim, uv=uv), tmp_path / "v")
    gltf = pygltflib.GLTF2.load(tmp_path / "v" / "result.glb")
    attributes = gltf.meshes[0].primitives[0].attributes
    assert gltf.accessors[attributes.POSITION].count == anim.vertex_count  # the page paints them
    assert attributes.TEXCOORD_0 is None


def test_write_viewer_mesh_sequence_and_rewrite(tmp_path):
    anim = deforming_sphere(frames=3)
    seq = MeshSequence(tuple(anim.frame(i) for i in range(3)))
    out = tmp_path / "v"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    viewer.write_viewer(seq, out)
    viewer.write_viewer(seq, out)  # rewriting is fine
    data = page_data(out)
    assert data["kind"] == "sequence" and len(data["frames"]) == 3
    assert "glb" not in data
    v1 = decode(data["frames"][1]["positions"], "<f4", (-1, 3))
    assert np.allclose(v1, anim.vertices[1], atol=1e-6)
    assert (out / "keep.txt").read_text() == "mine"  # other files left alone


def test_write_viewer_bad_input(tmp_path):
    anim = deforming_sphere(frames=2)
    with pytest.raises(InputError, match="parent"):
        viewer.write_viewer(anim, tmp_path / "missing" / "view")
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        viewer.write_viewer(anim, tmp_path / "file")
    with pytest.raises(InputError, match="metrics"):
        viewer.write_viewer(anim, tmp_path / "v", metrics=tmp_path / "nope.json")
    with pytest.raises(InputError):
        viewer.write_viewer(object(), tmp_path / "v")
    (tmp_path / "other.html").write_text("<html></html>")
    with pytest.raises(InputError, match="not a fourd viewer page"):
        viewer.read_viewer_data(tmp_path / "other.html")


def test_write_viewer_from_saved_result_and_metrics_file(tmp_path):
    results = pytest.importorskip("fourd.io.results")
    anim = deforming_sphere(frames=3)
    results.save(anim, tmp_path / "result.npz")
    (tmp_path / "metrics.json").write_text(json.dumps({"hausdorff": 0.5}))
    viewer.write_viewer(tmp_path / "result.npz", tmp_path / "v", metrics=tmp_path / "metrics.json")
    data = page_data(tmp_path / "v")
    assert data["metrics"] == {"hausdorff": 0.5}
    positions = decode(data["positions"], "<f4", anim.vertices.shape)
    assert np.allclose(positions, anim.vertices, atol=1e-6)


def test_the_page_has_an_error_legend_and_whole_metric_keys(tmp_path):
    """The legend (colour bar, ticks, what the colours mean) is in the page, and the metrics
    table no longer breaks its key names at any letter (tests/viz/test_viewer_browser.py
    measures both in Chromium)."""
    index = viewer.write_viewer(deforming_sphere(frames=2), tmp_path / "v")
    page = index.read_text()
    for element in ("fourd-error-legend", "fourd-colorbar", "fourd-colorbar-hi", "fourd-colorbar-text"):
        assert f'id="{element}"' in page
    css = (tmp_path / "v" / "viewer.css").read_text()
    assert "break-all" not in css and "td.fourd-key" in css
    assert 'createElement("wbr")' in page
