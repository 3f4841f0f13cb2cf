"""The default method: its decision rule on known shapes, and its result on small scenes."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh

from fourd import AnimatedMesh, MeshSequence, synth
from fourd.geometry.neighbors import point_spacing
from fourd.geometry.normals import vertex_normals
from fourd.methods import DEFAULT_METHOD, reconstruct_with_diagnostics
from fourd.methods.auto import Options, fit_to_frames, part_counts, splits, vector_area_fraction
from fourd.metrics import evaluate


def test_vector_area_is_zero_when_closed_half_for_a_hemisphere_and_one_for_a_sheet():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    assert vector_area_fraction(sphere.vertices, sphere.faces) < 1e-12
    upper = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] > 0
    # projected area pi r^2 over the surface 2 pi r^2
    assert vector_area_fraction(sphere.vertices, sphere.faces[upper]) == pytest.approx(0.5, abs=0.02)
    sheet = trimesh.creation.box(extents=(1, 1, 0.001))
    top = sheet.face_normals[:, 2] > 0.9
    assert vector_area_fraction(sheet.vertices, sheet.faces[top]) == pytest.approx(1.0)


def test_part_counts_ignore_small_pieces_and_splits_need_a_lasting_change():
    a = trimesh.creation.icosphere(subdivisions=2)
    b = a.copy()
    b.apply_translation([3, 0, 0])
    crumb = trimesh.creation.box(extents=(0.1, 0.1, 0.1))  # 12 of 332 faces
    crumb.apply_translation([0, 3, 0])
    one = (a.vertices, a.faces)
    two = trimesh.util.concatenate([a, b])
    with_crumb = trimesh.util.concatenate([a, crumb])
    meshes = MeshSequence((one, (two.vertices, two.faces), (with_crumb.vertices, with_crumb.faces)))
    assert part_counts(meshes, 0.05).tolist() == [1, 2, 1]
    assert splits(np.array([1, 1, 1, 1, 2, 2, 2, 2]))
    assert splits(np.array([2, 2, 2, 1, 1, 1]))  # a merge
    assert not splits(np.array([1, 1, 2, 1, 1, 1, 2, 1]))  # flicker


def test_options_are_checked():
    with pytest.raises(ValueError, match="surface"):
        Options(surface="half")
    with pytest.raises(ValueError, match="open_area"):
        Options(open_area=0.0)


def test_the_default_method_is_auto():
    assert DEFAULT_METHOD == "auto"


@pytest.mark.slow
def test_a_sheet_is_an_open_surface_and_gives_the_kinematic_animation():
    from fourd.methods import kinematic

    truth = synth.scene("waving-sheet", frames=4)
    scans = synth.scan(truth, resolution=96, seed=0)
    result, diagnostics = reconstruct_with_diagnostics(scans)
    assert isinstance(result, AnimatedMesh) and diagnostics.open_surface == 1.0
    assert diagnostics.vector_area > 0.5
    opened = kinematic.reconstruct(scans)
    expected = fit_to_frames(scans, opened, Options())
    assert np.array_equal(result.vertices, expected.vertices)
    assert np.array_equal(result.faces, opened.faces)
    unfitted = reconstruct_with_diagnostics(scans, options=Options(fit_frames=False)).result
    assert np.array_equal(unfitted.vertices, opened.vertices)


@pytest.mark.slow
def test_a_closed_object_gives_one_closed_animated_mesh_on_the_kinematic_result(closed_squash):
    """Closed and manifold in every frame, the vertices bound to the kinematic result on its
    surface, and holes filled: completeness-95 better than the per-frame baseline's."""
    from fourd.methods import kinematic, reconstruct

    truth, scans, memory, metrics, _ = closed_squash
    result, diagnostics = memory
    assert isinstance(result, AnimatedMesh)
    assert (diagnostics.open_surface, diagnostics.split) == (0.0, 0.0)
    assert metrics["closed_manifold"] == 1.0
    baseline = evaluate(reconstruct(scans, "perframe"), truth, samples=10000)
    assert metrics["completeness_95"] < baseline["completeness_95"]
    opened = kinematic.reconstruct(scans)
    bound = result.observed[0]
    assert bound.mean() > 0.7
    for t in range(len(result.times)):
        surface = trimesh.Trimesh(opened.vertices[t], opened.faces, process=False)
        _, distance, _ = trimesh.proximity.closest_point(surface, result.vertices[t][bound])
        assert distance.max() < 1e-4  # on it, up to the round-off of sliver triangles


@pytest.mark.slow
def test_fitting_to_the_frames_moves_vertices_towards_the_truth_along_their_normals():
    truth = synth.scene("squash-ball", frames=4)
    # dense enough (about 11,000 points per frame) for kinematic's full-size template without
    # densifying the frames
    scans = synth.scan(truth, resolution=180, seed=0)
    unfitted = reconstruct_with_diagnostics(
        scans, options=Options(resolution=20, fit_frames=False)
    ).result
    fitted = fit_to_frames(scans, unfitted, Options())
    before = evaluate(unfitted, truth, samples=10000)
    after = evaluate(fitted, truth, samples=10000)
    assert after["accuracy"] < before["accuracy"]
    assert after["correspondence_mean"] <= before["correspondence_mean"] * 1.01
    spacing = point_spacing(scans.frames[0].points)
    moved = np.linalg.norm(fitted.vertices - unfitted.vertices, axis=2)
    assert moved.max() <= 4 * spacing * 1.001  # fit_reach caps it
    normals = np.stack([vertex_normals(v, unfitted.faces) for v in unfitted.vertices])
    along = np.abs(np.einsum("tni,tni->tn", fitted.vertices - unfitted.vertices, normals))
    # the first iteration's step is along these normals, the second along slightly turned ones
    assert np.median(along / np.maximum(moved, 1e-12)) > 0.99


@pytest.mark.slow
def test_a_shape_that_splits_gives_the_flow_meshes_and_a_warning(caplog):
    truth = synth.scene("splitting-blob", frames=8)
    scans = synth.scan(truth, resolution=96, seed=0)
    with caplog.at_level(logging.WARNING, logger="fourd.methods.auto"):
        result, diagnostics = reconstruct_with_diagnostics(scans, options=Options(resolution=24))
    assert isinstance(result, MeshSequence) and diagnostics.split == 1.0
    assert "splits or merges" in caplog.text
    counts = part_counts(result, 0.05)
    assert counts[0] == 1 and counts[-1] == 2


def test_the_cache_folder_goes_to_the_methods_it_runs(monkeypatch, tmp_path):
    """``cache_dir`` reaches the kinematic and the flow runs, each in a folder of its own."""
    from fourd.methods import auto, flow, kinematic

    seen = {}

    class Stop(Exception):
        pass

    def opened(seq, options):
        seen["kinematic"] = options.cache_dir
        anim = AnimatedMesh(faces=np.array([[0, 1, 2]]), vertices=np.zeros((2, 3, 3)),
                            times=np.arange(2.0), rest=np.eye(3))
        return anim

    def flowed(seq, options):
        seen["flow"] = options.cache_dir
        raise Stop

    monkeypatch.setattr(kinematic, "reconstruct", opened)
    monkeypatch.setattr(flow, "run", flowed)
    seq = synth.scan(synth.scene("squash-ball", frames=2), resolution=32, seed=0)
    with pytest.raises(Stop):
        auto.reconstruct(seq, Options(surface="closed", cache_dir=str(tmp_path)))
    assert seen == {"kinematic": str(tmp_path / "kinematic"), "flow": str(tmp_path / "flow")}
    with pytest.raises(Stop):
        auto.reconstruct(seq, Options(surface="closed"))
    assert seen == {"kinematic": None, "flow": None}
