"""``fourd info`` on results in every format fourd writes, and on inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.cli import main
from fourd.info import describe
from fourd.io.results import save


def _animation(frames=4) -> AnimatedMesh:
    sphere = trimesh.creation.icosphere(subdivisions=1)
    vertices = np.stack([sphere.vertices * (1 + 0.1 * t) + [0.1 * t, 0, 0] for t in range(frames)])
    observed = np.ones((frames, len(sphere.vertices)), bool)
    observed[1, :21] = False  # 21 of 4 x 42 vertex-frames: 12.5%
    return AnimatedMesh(sphere.faces, vertices, times=np.arange(frames) + 2.0, observed=observed)


def _sequence() -> MeshSequence:
    a = trimesh.creation.icosphere(subdivisions=1)
    b = trimesh.creation.box()
    return MeshSequence(((a.vertices, a.faces), (b.vertices, b.faces)), times=[0.0, 1.0])


def _lines(text: str) -> dict[str, str]:
    return dict(line.split(": ", 1) for line in text.splitlines()[1:])


@pytest.mark.parametrize(
    ("suffix", "format_name", "filled"),
    [
        (".npz", "fourd .npz", "12.5% of vertex-frames"),
        (".glb", "glTF binary (.glb)", "not stored in this format"),
        (".usda", "USD stage", "not stored in this format"),
        (".pc2", "point cache (.pc2 with its .obj)", "not stored in this format"),
        ("/", "folder of per-frame meshes", "12.5% of vertex-frames"),
    ],
)
def test_info_describes_an_animated_mesh_in_every_format(tmp_path, suffix, format_name, filled):
    if suffix == ".usda":
        pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    target = str(tmp_path / "walk") + suffix
    save(_animation(), target)
    text = describe(target)
    assert text.splitlines()[0].endswith(f": result, {format_name}")
    lines = _lines(text)
    assert lines["kind"] == "animated mesh"
    assert lines["connectivity"].startswith("one for all 4 frames")
    assert lines["frames"] == "4, times 2 .. 5"
    assert (lines["vertices"], lines["faces"]) == ("42", "80")
    assert lines["surface"] == "closed and manifold, 1 piece, genus 0"
    assert lines["filled in (not observed)"] == filled


@pytest.mark.parametrize("suffix", [".npz", ".glb", "/"])
def test_info_describes_per_frame_meshes(tmp_path, suffix):
    target = str(tmp_path / "seq") + suffix
    save(_sequence(), target)
    lines = _lines(describe(target))
    assert lines["kind"] == "per-frame meshes"
    assert lines["connectivity"].startswith("each frame its own")
    assert lines["frames"] == "2, times 0 .. 1"
    assert lines["vertices per frame"] == "8 .. 42" and lines["faces per frame"] == "12 .. 80"
    assert lines["surface"] == "2 of 2 frames closed and manifold"


def test_a_result_folder_is_not_read_as_scans(tmp_path, capsys):
    """observed.npy beside the meshes is the result's flags, not one more frame."""
    save(_animation(frames=3), tmp_path / "out")
    assert (tmp_path / "out" / "observed.npy").is_file()
    assert main(["info", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "result, folder of per-frame meshes" in out and "frames: 3," in out


def test_a_scan_folder_is_an_input(tmp_path):
    folder = tmp_path / "scans"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):
        np.save(folder / f"frame_{k}.npy", rng.normal(size=(50, 3)))
    (folder / "sensors.json").write_text(json.dumps({"sensors": [[0, 0, 5]]}))
    text = describe(folder)
    assert text.splitlines()[0].endswith(": input")
    assert "point cloud sequence: 3 frames" in text


def test_info_problems_are_one_line(tmp_path, capsys):
    assert main(["info", str(tmp_path / "none.glb")]) == 2
    assert "none.glb: does not exist" in capsys.readouterr().err
    (tmp_path / "bad.glb").write_text("not a glb")
    assert main(["info", str(tmp_path / "bad.glb")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.glb: not a glTF binary" in err


def test_info_tells_a_closed_surface_its_genus_and_an_open_one_its_holes():
    """What a user checks before texturing or printing: closed and manifold (and the genus),
    or the boundary loops, the sides of more than two faces and the pinched vertices that keep
    it from being so."""
    from fourd.info import describe_surface

    sphere = trimesh.creation.icosphere(subdivisions=2)
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    two = np.vstack([torus.faces, sphere.faces + len(torus.vertices)])
    assert describe_surface(sphere.faces, len(sphere.vertices)) == "closed and manifold, 1 piece, genus 0"
    assert describe_surface(torus.faces, len(torus.vertices)) == "closed and manifold, 1 piece, genus 1"
    assert describe_surface(two, len(torus.vertices) + len(sphere.vertices)) == (
        "closed and manifold, 2 pieces, genus 1"
    )
    assert describe_surface(sphere.faces[1:], len(sphere.vertices)) == "not closed (1 boundary loop), 1 piece"
    doubled = np.vstack([sphere.faces, sphere.faces[:1]])  # one face twice: three sides of 3 faces
    assert describe_surface(doubled, len(sphere.vertices)) == (
        "closed but not manifold (3 sides shared by more than two faces), 1 piece"
    )
    count = len(sphere.vertices)
    touching = np.vstack([sphere.faces, np.where(sphere.faces == 0, 0, sphere.faces + count)])  # share vertex 0
    assert describe_surface(touching, 2 * count) == (
        "closed but not manifold (1 pinched vertex where faces touch at a point only), 1 piece"
    )
