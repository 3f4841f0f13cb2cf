"""The default method streamed (issue 56): the fit's chunks give the whole fit, and the
streamed run is the in-memory one, in one window and over several."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from fourd import AnimatedMesh
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
