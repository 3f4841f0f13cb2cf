import base64
import io
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


# ---------------------------------------------------------------- carried colour and video


@pytest.fixture(scope="module")
def filmed():
    """A small filmed capture: 3 frames of a deforming sphere, 2 cameras, coloured points,
    48-pixel images (the sizes of tests/appearance's small video scenes)."""
    import fourd

    anim = deforming_sphere(frames=3)
    anim = AnimatedMesh(anim.faces, anim.vertices)  # every vertex observed
    scans = fourd.synth.scan(
        anim, resolution=32, cameras=2, appearance="cloth", video=True, video_resolution=48,
        outliers=0.0,
    )
    return anim, scans


def test_carried_colours_are_frame_0s_vertex_colours_on_every_frame(filmed):
    from fourd.appearance import vertex_colors

    anim, scans = filmed
    data = viewer.viewer_data(anim, scans=scans, carried_colors=True)
    carried = decode(data["carriedColors"], "u1", (anim.vertex_count, 3))
    frame0 = vertex_colors(anim, scans)[0]
    assert np.abs(carried / 255.0 - frame0).max() <= 0.5 / 255 + 1e-9
    # one array for all frames: the page sets it on every frame, where the error colouring
    # has one per frame
    assert "errors" not in data and data["frameCount"] == 3
    # the points beside them, in their own colours per frame
    assert len(data["pointColors"]) == len(data["points"]) == 3
    for t, (points, colours) in enumerate(zip(data["points"], data["pointColors"], strict=True)):
        count = len(scans[t].points)
        assert np.allclose(decode(points, "<f4", (count, 3)), scans[t].points, atol=1e-6)
        assert np.abs(decode(colours, "u1", (count, 3)) / 255.0 - scans[t].colors).max() <= 0.5 / 255 + 1e-9
    # off unless asked, or asked as None ("when the input has colours")
    assert "carriedColors" not in viewer.viewer_data(anim, scans=scans)
    assert "carriedColors" in viewer.viewer_data(anim, scans=scans, carried_colors=None)


def test_video_panel_has_one_capped_image_per_frame_and_camera(filmed):
    from PIL import Image

    anim, scans = filmed
    data = viewer.viewer_data(anim, scans=scans, video=True, video_size=20)
    panel = data["video"]
    assert panel["downscaled"] and panel["size"] == 20
    assert [c["name"] for c in panel["cameras"]] == list(scans.video.names)
    for c, camera in enumerate(panel["cameras"]):
        assert (camera["width"], camera["height"]) == (48, 48)
        assert (camera["shownWidth"], camera["shownHeight"]) == (20, 20)
        assert np.allclose(camera["K"], scans.video.cameras[c].K)
        assert len(camera["images"]) == anim.frame_count
        for t, url in enumerate(camera["images"]):
            assert url.startswith("data:image/jpeg;base64,")
            image = Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1])))
            assert image.size == (20, 20)
            full = scans.video.image(c, t).mean(axis=(0, 1))
            assert np.abs(np.asarray(image.convert("RGB")).mean(axis=(0, 1)) - full).max() < 12
    whole = viewer.viewer_data(anim, scans=scans, video=None)["video"]  # None: when there is one
    assert not whole["downscaled"] and whole["cameras"][0]["shownWidth"] == 48


def test_video_panel_follows_the_input_frame_of_each_result_frame(filmed):
    anim, scans = filmed
    every_other = anim.select(0, 3, 2)  # result frames at times 0 and 2
    panel = viewer.viewer_data(every_other, scans=scans, video=True)["video"]
    full = viewer.viewer_data(anim, scans=scans, video=True)["video"]
    assert panel["cameras"][1]["images"] == [full["cameras"][1]["images"][t] for t in (0, 2)]


def test_carried_colours_and_video_refuse_what_cannot_give_them(tmp_path, filmed):
    from fourd.io.frames import write_frames

    anim, scans = filmed
    plain = PointCloudSequence.from_arrays([v[::3] for v in anim.vertices])
    plain_folder = tmp_path / "plain"
    write_frames(plain, plain_folder)
    with pytest.raises(InputError, match=f"{plain_folder}: has no colours"):
        viewer.viewer_data(anim, scans=plain_folder, carried_colors=True)
    with pytest.raises(InputError, match=f"{plain_folder}: has no video"):
        viewer.viewer_data(anim, scans=plain_folder, video=True)
    with pytest.raises(InputError, match="need the input scans"):
        viewer.viewer_data(anim, carried_colors=True)
    with pytest.raises(InputError, match="needs the input scans"):
        viewer.viewer_data(anim, video=True)
    sequence = MeshSequence(  # the last frame with its own connectivity
        tuple(anim.frame(i) for i in range(2)) + ((anim.vertices[2], anim.faces[1:]),)
    )
    results = pytest.importorskip("fourd.io.results")
    results.save(sequence, tmp_path / "meshes")
    with pytest.raises(InputError, match=r"meshes: carried colours need an animated mesh"):
        viewer.write_viewer(tmp_path / "meshes", tmp_path / "v", scans=scans, carried_colors=True)
    assert not (tmp_path / "v").exists()  # nothing written for a bad request
    with pytest.raises(InputError, match="video size"):
        viewer.viewer_data(anim, scans=scans, video=True, video_size=4)
    # asked as None, neither is an error: a mesh sequence and plain points just go without
    data = viewer.viewer_data(sequence, scans=plain, carried_colors=None, video=None)
    assert "carriedColors" not in data and "video" not in data
