"""The default method streamed (issue 56): the fit's chunks give the whole fit, and the
streamed run is the in-memory one, in one window and over several."""

from __future__ import annotations

import dataclasses
import logging
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from fourd import AnimatedMesh, Frame, MeshSequence
from fourd.frame_source import FrameSource
from fourd.geometry.surface_fit import fit_along_normals
from fourd.io.npz import read_npz
from fourd.methods import auto
from fourd.methods.auto import stream
from fourd.metrics import evaluate


def test_the_fit_in_chunks_is_the_fit_of_the_whole_sequence(monkeypatch):
    """Chunks of three frames with two frames of margin on both sides: every frame as the
    fit of all nine frames at once gives it."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(0)
    count = 9
    vertices = np.stack([sphere.vertices * (1 + 0.01 * t) for t in range(count)])
    observed = rng.random((count, len(sphere.vertices))) > 0.5
    points = []
    for t in range(count):
        directions = rng.normal(size=(600, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        points.append(directions * (1.05 + 0.02 * np.sin(t)) + rng.normal(scale=0.005, size=(600, 3)))
    options = auto.Options()
    scales = (0.2, 0.2)
    whole = fit_along_normals(
        vertices, sphere.faces, auto.fit_points(points), radius=scales[0], reach=scales[1]
    ).vertices
    monkeypatch.setattr(stream, "FIT_CHUNK", 3)
    frames = zip(vertices, observed, points, strict=True)
    chunks = list(stream._fitted(frames, sphere.faces, count, options, scales))
    assert [len(v) for v, _ in chunks] == [3, 3, 3]
    np.testing.assert_allclose(np.concatenate([v for v, _ in chunks]), whole, atol=1e-12)
    np.testing.assert_array_equal(np.concatenate([o for _, o in chunks]), observed)
    assert np.abs(whole - vertices).max() > 0.01  # the fit moved them
    unfitted = list(stream._fitted(zip(vertices, observed, points, strict=True), sphere.faces, count, options, None))
    np.testing.assert_array_equal(np.concatenate([v for v, _ in unfitted]), vertices)


@pytest.mark.slow
def test_streamed_in_one_window_is_the_in_memory_result(closed_squash, tmp_path):
    """The same decision on the same figures, one closed animated mesh as accurate as the
    in-memory run's (only the flow's signed distance differs: from its meshes alone)."""
    truth, scans, memory, theirs, options = closed_squash
    summary = auto.reconstruct_streamed(FrameSource.of(scans), tmp_path / "out.npz", options)
    assert list(tmp_path.iterdir()) == [tmp_path / "out.npz"]  # the work folder is gone
    streamed = read_npz(summary.output)
    assert isinstance(streamed, AnimatedMesh) and summary.frames == 4
    assert summary.vertices == len(streamed.rest) and summary.windows == 2  # kinematic, flow
    ours, expected = summary.diagnostics, memory.diagnostics
    assert (ours.open_surface, ours.split) == (expected.open_surface, expected.split) == (0, 0)
    assert ours.vector_area == pytest.approx(expected.vector_area, abs=1e-6)
    assert ours.mass_conservation_error == pytest.approx(expected.mass_conservation_error)
    metrics = evaluate(streamed, truth, samples=10000)
    assert metrics["closed_manifold"] == 1.0
    for name in ("accuracy", "completeness_95", "correspondence_mean", "correspondence_last"):
        assert metrics[name] == pytest.approx(theirs[name], rel=0.05), name
    assert abs(len(streamed.rest) - len(memory.result.rest)) < 0.02 * len(memory.result.rest)


@pytest.mark.slow
def test_streamed_over_windows_stays_closed_and_fitted(closed_squash, tmp_path):
    """Windows of three frames (two of each stage), fitted to the frames: closed in every
    frame and at least as accurate as one window unfitted."""
    truth, scans, _, theirs, options = closed_squash
    options = dataclasses.replace(options, window=3, fit_frames=True)
    summary = auto.reconstruct_streamed(FrameSource.of(scans), tmp_path / "out.npz", options)
    assert summary.windows == 4
    metrics = evaluate(read_npz(summary.output), truth, samples=10000)
    assert metrics["closed_manifold"] == 1.0
    assert metrics["accuracy"] < theirs["accuracy"]
    assert metrics["completeness_95"] < 1.25 * theirs["completeness_95"]
    assert metrics["correspondence_mean"] < 1.25 * theirs["correspondence_mean"]


SPHERE = trimesh.creation.icosphere(subdivisions=3)


def _fake_stages(monkeypatch, opened_faces, flow_meshes):
    """The kinematic and flow stages replaced by writers of known results: :data:`SPHERE`
    (``opened_faces`` of it) shrunk to radius 0.98 and moving by 0.05 per frame, and
    ``flow_meshes`` per frame; the frames are 2,000 points on the moving unit sphere."""
    from fourd.io.npz import write_npz
    from fourd.methods import flow, kinematic

    count = len(flow_meshes)
    vertices = np.stack([0.98 * SPHERE.vertices + 0.05 * t for t in range(count)])

    def opened(source, path, options):
        write_npz(path, AnimatedMesh(opened_faces, vertices, times=source.times, rest=vertices[0]))
        return SimpleNamespace(windows=1, resumed=0)

    def flowed(source, path, options):
        write_npz(path, MeshSequence(tuple(flow_meshes), source.times))
        return SimpleNamespace(windows=1, resumed=0, mass_error=0.01, spacing=0.1)

    monkeypatch.setattr(kinematic, "reconstruct_streamed", opened)
    monkeypatch.setattr(flow, "reconstruct_streamed", flowed)
    rng = np.random.default_rng(0)
    frames = []
    for t in range(count):
        directions = rng.normal(size=(2000, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        frames.append(Frame(directions + 0.05 * t, time=float(t)))
    return vertices, FrameSource.of_frames(frames)


def test_an_open_surface_streamed_is_the_kinematic_result_fitted(monkeypatch, tmp_path):
    upper = SPHERE.faces[SPHERE.vertices[SPHERE.faces].mean(axis=1)[:, 2] > 0]
    vertices, source = _fake_stages(monkeypatch, upper, [None] * 5)
    summary = auto.reconstruct_streamed(source, tmp_path / "out.npz")
    result = read_npz(summary.output)
    assert summary.diagnostics.open_surface == 1.0 and summary.diagnostics.vector_area > 0.5
    np.testing.assert_array_equal(result.faces, upper)
    radius = np.linalg.norm(result.vertices - 0.05 * np.arange(5)[:, None, None], axis=2)
    assert np.abs(radius[:, np.unique(upper)] - 1.0).max() < 3e-3  # onto the points' sphere
    unfitted = auto.reconstruct_streamed(source, tmp_path / "b.npz", auto.Options(fit_frames=False))
    np.testing.assert_allclose(read_npz(unfitted.output).vertices, vertices, atol=1e-6)


def test_a_split_streamed_gives_the_flow_meshes(monkeypatch, tmp_path, caplog):
    one = trimesh.creation.icosphere(subdivisions=2)
    two = trimesh.util.concatenate([one, one.copy().apply_translation([3, 0, 0])])
    meshes = [(one.vertices, one.faces)] * 4 + [(two.vertices, two.faces)] * 4
    _, source = _fake_stages(monkeypatch, SPHERE.faces, meshes)
    with caplog.at_level(logging.WARNING, logger="fourd.methods.auto"):
        summary = auto.reconstruct_streamed(source, tmp_path / "out.npz")
    assert "splits or merges" in caplog.text and summary.diagnostics.split == 1.0
    result = read_npz(summary.output)
    assert isinstance(result, MeshSequence) and result.frame_count == 8
    assert len(result.meshes[-1][1]) == 2 * len(one.faces)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.npz"]


def test_a_flow_that_lacks_a_part_streamed_gives_the_kinematic_result(monkeypatch, tmp_path):
    """The flow's surface is half the sphere's size: it lacks the tracked first frame."""
    small = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    _, source = _fake_stages(monkeypatch, SPHERE.faces, [(small.vertices, small.faces)] * 4)
    summary = auto.reconstruct_streamed(source, tmp_path / "out.npz", auto.Options(surface="closed"))
    assert summary.diagnostics.open_surface == 1.0 and summary.diagnostics.lost > 0.9
    np.testing.assert_array_equal(read_npz(summary.output).faces, SPHERE.faces)
