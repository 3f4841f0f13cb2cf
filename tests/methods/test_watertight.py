"""The watertight composition: the kinematic result closed by the flow's surfaces."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from fourd import AnimatedMesh, synth
from fourd.methods import method_options, resolve_alias
from fourd.methods.flow import FlowField
from fourd.methods.watertight import (
    Options,
    WatertightDiagnostics,
    close_animation,
    off_surface_fractions,
    reconstruct,
    reconstruct_with_diagnostics,
)
from fourd.metrics.topology import topology

FAST = dict(resolution=16, max_iterations=6, refine=2)


def _squash_scans(frames):
    return synth.scan(synth.scene("squash-ball", frames=frames), resolution=96, seed=0)


def _check_closed_manifold(vertices, faces):
    assert topology(faces, len(vertices)).closed_manifold
    assert trimesh.Trimesh(vertices, faces, process=False).volume > 0, "faces must wind outwards"


def test_flow_coherent_is_an_alias_of_watertight():
    assert resolve_alias("flow", {"coherent": "true", "resolution": "20"}) == (
        "watertight", {"resolution": "20"}
    )
    assert resolve_alias("flow", {"coherent": "false"}) == ("flow", {})
    options = method_options("flow", {"coherent": "true", "resolution": "20"})
    assert isinstance(options, Options) and options.resolution == 20


class _MovingSphere:
    """The signed distance of a unit sphere rotated by ``rotations[k]`` about the origin and
    moved by ``shifts[k]`` at time k (a Field4D; the sphere's distance is rotation-free)."""

    def __init__(self, shifts):
        self.shifts = np.asarray(shifts, float)

    def _centre(self, times, count):
        k = np.clip(np.rint(np.broadcast_to(times, (count,))).astype(int), 0, len(self.shifts) - 1)
        return self.shifts[k]

    def value(self, points, times):
        return np.linalg.norm(points - self._centre(times, len(points)), axis=1) - 1.0

    def gradient(self, points, times):
        d = points - self._centre(times, len(points))
        g = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        return np.hstack([g, np.zeros((len(points), 1))])


def _rotation(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_close_animation_carries_the_hole_along_a_known_rigid_motion():
    """A unit sphere open at its top (the first frame never saw it) turns and moves rigidly:
    closed by the sphere's own signed distance, every frame is closed and manifold, the
    vertices bound to the open mesh follow it exactly, and the cap's vertices (carried
    along) follow the known rigid motion within a fraction of an edge."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    keep = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] < 0.6
    open_mesh = trimesh.Trimesh(sphere.vertices, sphere.faces[keep], process=False)
    open_mesh.remove_unreferenced_vertices()
    frames = 4
    rotations = [_rotation(0.3 * k) for k in range(frames)]
    shifts = np.array([[0.2 * k, 0.1 * k, 0.0] for k in range(frames)])
    opened = AnimatedMesh(
        faces=open_mesh.faces,
        vertices=np.stack([open_mesh.vertices @ r.T + t for r, t in zip(rotations, shifts, strict=True)]),
        times=np.arange(frames, dtype=float),
    )
    bounds = np.array([[-1.2] * 3, [1.2] * 3])
    closed = close_animation(opened, _MovingSphere(shifts), bounds=bounds, cell_size=0.1)
    bound = closed.observed[0]
    assert 0.02 < (~bound).mean() < 0.3  # the cap is carried along, the rest is bound
    edge = 0.1 * 0.6
    for k in range(frames):
        _check_closed_manifold(closed.vertices[k], closed.faces)
        expected = closed.rest @ rotations[k].T + shifts[k]
        error = np.linalg.norm(closed.vertices[k] - expected, axis=1)
        assert error[bound].max() < 1e-9
        assert error[~bound].mean() < 0.25 * edge and error[~bound].max() < edge, k
        radius = np.linalg.norm(closed.vertices[k] - shifts[k], axis=1)
        assert np.abs(radius - 1.0).max() < 0.02


@pytest.mark.slow
def test_watertight_is_closed_and_its_observed_part_is_the_kinematic_result():
    """On a squashing ellipsoid: one closed, manifold connectivity for every frame, every
    vertex near its frame's ellipsoid, and the vertices bound to the kinematic result lie on
    that result's surface in every frame (closing adds no drift of its own)."""
    from fourd.methods import kinematic

    frames = 4
    seq = _squash_scans(frames)
    anim, figures = reconstruct_with_diagnostics(seq, Options(**FAST))
    opened = kinematic.reconstruct(seq)
    assert anim.vertices.shape[0] == frames and len(anim.faces)
    assert figures.off_surface == 0.0 and figures.lost < 0.02
    bound = anim.observed[0]
    assert bound.mean() > 0.7
    for t in range(frames):
        _check_closed_manifold(anim.vertices[t], anim.faces)
        surface = trimesh.Trimesh(opened.vertices[t], opened.faces, process=False)
        _, distance, _ = trimesh.proximity.closest_point(surface, anim.vertices[t][bound])
        assert distance.max() < 1e-4  # on it, up to the round-off of sliver triangles


@pytest.mark.slow
def test_watertight_closes_a_frame_the_flow_reconstructs_without_data():
    """With frame 0 missing from the flow (``missing_frames``), its surface there comes from
    the flow alone, and the closed result is still closed in every frame."""
    seq = _squash_scans(4)
    anim = reconstruct(seq, Options(**FAST, missing_frames=(0,)))
    assert anim.vertices.shape[0] == 4 and np.allclose(anim.times, seq.times)
    for t in range(4):
        _check_closed_manifold(anim.vertices[t], anim.faces)
    assert not np.allclose(anim.vertices[0], anim.vertices[1])


def test_off_surface_fractions_count_vertices_far_from_the_surface_and_the_points():
    """A sphere's signed distance: vertices on it are on; a piece 1.0 away is off, unless its
    frame has points there."""
    h = 0.1
    axes = [-2.0 + h * np.arange(41)] * 3
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    distance = (np.linalg.norm(grid, axis=-1) - 1.0).astype(np.float32)
    field = FlowField(np.stack([distance, distance]), np.full(3, -2.0), h, np.array([0.0, 1.0]))
    rng = np.random.default_rng(0)
    on = rng.normal(size=(90, 3))
    on /= np.linalg.norm(on, axis=1, keepdims=True)
    piece = np.array([0.0, 0.0, 2.0]) + 0.01 * rng.normal(size=(10, 3))
    vertices = np.concatenate([on, piece])
    anim = AnimatedMesh(
        faces=np.array([[0, 1, 2]]), vertices=np.stack([vertices, vertices]),
        times=np.array([0.0, 1.0]),
    )
    np.testing.assert_allclose(off_surface_fractions(anim, field, 3 * h), [0.1, 0.1])
    np.testing.assert_allclose(
        off_surface_fractions(anim, field, 3 * h, [on, vertices]), [0.1, 0.0]
    )




@pytest.mark.slow
def test_a_cached_run_keeps_both_methods_stages_and_a_rerun_computes_none(tmp_path, monkeypatch):
    from fourd.methods.flow import irls
    from fourd.methods.kinematic import frames, sliding

    scans = synth.scan(synth.scene("squash-ball", frames=3), resolution=64, seed=0)
    options = Options(resolution=10, max_outer=8, cache_dir=str(tmp_path))
    first = reconstruct(scans, options)
    assert list((tmp_path / "kinematic").glob("kinematic-slide-*.npz"))
    assert list((tmp_path / "flow").glob("flow-post-*.npz"))
    assert not list(tmp_path.glob("*.npz"))

    calls = []
    for module, name in ((frames, "_prepare_frame"), (sliding, "slide_step"), (irls, "solve_saddle")):
        monkeypatch.setattr(module, name, lambda *a, _name=name, **k: calls.append(_name))
    again = reconstruct(scans, options)
    assert calls == []
    assert np.array_equal(first.vertices, again.vertices) and np.array_equal(first.faces, again.faces)


@pytest.mark.slow
def test_in_windows_it_stays_closed_as_accurate_as_one_solve_and_without_a_jump_at_the_seams():
    """Six frames in windows of four (the kinematic and the flow stages streamed, the flow's
    windows sharing one frame) against one solve: closed, as accurate, and the second
    difference of the positions over time no larger at any frame (no jump at a seam)."""
    from fourd.metrics import evaluate

    truth = synth.scene("squash-ball", frames=6)
    seq = synth.scan(truth, resolution=96, seed=0)
    whole = reconstruct(seq, Options(**FAST))
    windowed, figures = reconstruct_with_diagnostics(seq, Options(**FAST, window=4, window_overlap=1))
    assert isinstance(figures, WatertightDiagnostics) and figures.off_surface == 0.0
    _check_closed_manifold(windowed.vertices[0], windowed.faces)
    ours, theirs = (evaluate(a, truth, samples=10000) for a in (windowed, whole))
    assert ours["closed_manifold"] == 1.0
    for name in ("accuracy", "completeness_95", "correspondence_mean"):
        assert ours[name] < 1.25 * theirs[name], name

    def jerk(animation):
        v = animation.vertices
        return np.median(np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=2), axis=1)

    assert np.all(jerk(windowed) < 1.1 * jerk(whole))
