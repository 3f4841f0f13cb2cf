"""The rest fit (``Options.rest_fit``): each assembled frame slid along its own surface towards
the shape most as-rigid-as-possible to the first frame. A bumpy sphere turning rigidly: the
truth is a fixed point, a chain of slides that grows frame by frame is taken back, and a
stopped fit resumes at the frame it had not kept."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from fourd.cache import StageCache
from fourd.geometry.closest_point import closest_points_on_mesh
from fourd.methods.assembly import rest_fit
from fourd.methods.assembly.rest_fit import RestFit, fit_rest


def _bumpy_sphere():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    unit = np.asarray(sphere.vertices)
    vertices = unit * (1.0 + 0.15 * np.sin(3.0 * unit[:, [0]]) * np.cos(2.0 * unit[:, [1]]))
    faces = np.asarray(sphere.faces, dtype=np.int64)
    edge = float(
        np.median(np.linalg.norm(vertices[faces] - vertices[np.roll(faces, 1, axis=1)], axis=2))
    )
    return vertices, faces, edge


def _turning(frames: int):
    """The bumpy sphere turned and moved a little more each frame: ``[T, N, 3]``."""
    vertices, faces, edge = _bumpy_sphere()
    truth = np.stack(
        [
            vertices @ Rotation.from_rotvec([0.1 * t, -0.15 * t, 0.05 * t]).as_matrix().T
            + [0.1 * t, 0, 0]
            for t in range(frames)
        ]
    )
    return truth, faces, edge


def _twisted(truth, faces, twist: float):
    """Every frame's vertices slid along its surface by a twist about the first frame's z axis
    that grows with the frame (``twist`` radians per unit of height and frame), as a chain of
    maps' errors add up: the closest points of frame ``t``'s surface to the twisted vertices."""
    first = truth[0]
    slid = [first]
    for t in range(1, len(truth)):
        angle = twist * t * first[:, 2]
        cos, sin = np.cos(angle), np.sin(angle)
        turned = np.stack(
            [
                cos * first[:, 0] - sin * first[:, 1],
                sin * first[:, 0] + cos * first[:, 1],
                first[:, 2],
            ],
            axis=1,
        )
        # frame t's rigid motion, fitted from the truth (the twist is about the first frame's axes)
        centre0, centre = first.mean(axis=0), truth[t].mean(axis=0)
        u, _, vt = np.linalg.svd((first - centre0).T @ (truth[t] - centre))
        rotation = (u @ vt).T
        moved = (turned - centre0) @ rotation.T + centre
        slid.append(closest_points_on_mesh(truth[t], faces, moved).points)
    return np.stack(slid)


def test_the_truth_is_a_fixed_point():
    truth, faces, edge = _turning(4)
    observed = np.ones(truth.shape[:2], dtype=bool)
    fitted = fit_rest(truth, faces, observed, [(v, faces) for v in truth])
    assert np.abs(fitted - truth).max() < 1e-6 * edge


def test_a_twist_that_grows_along_the_chain_is_taken_back():
    truth, faces, edge = _turning(6)
    slid = _twisted(truth, faces, twist=0.08)
    observed = np.ones(truth.shape[:2], dtype=bool)
    observed[:, :40] = False  # a few vertices no frame observed move with their neighbours
    meshes = [(v, faces) for v in truth]
    fitted = fit_rest(slid, faces, observed, meshes)
    for t in range(1, len(truth)):
        before = np.linalg.norm(slid[t] - truth[t], axis=1) / edge
        after = np.linalg.norm(fitted[t] - truth[t], axis=1) / edge
        # measured: the twist 0.19-0.95 edges at the median, 0.03-0.12 after
        assert np.median(after) < 0.25 * np.median(before), (t, np.median(before), np.median(after))
        # the observed vertices stay on the frame's surface
        on = closest_points_on_mesh(truth[t], faces, fitted[t][observed[t]]).distances
        assert on.max() < 1e-9
    # the rounds are what does it: none leaves the twist as it is
    np.testing.assert_array_equal(fit_rest(slid, faces, observed, meshes, iterations=0), slid)


def test_a_part_that_slid_alone_is_taken_back_though_the_rest_has_settled():
    """Only the top 30% of the sphere twisted along the surface (a torso sliding after a
    kick): most vertices settle in the first rounds, and the rounds must go on for the part."""
    truth, faces, edge = _turning(2)
    first = truth[0]
    height = first[:, 2]
    top = height > np.percentile(height, 70)
    angle = np.where(top, 0.5 * (height - np.percentile(height, 70)), 0.0)
    cos, sin = np.cos(angle), np.sin(angle)
    turned = np.stack(
        [cos * first[:, 0] - sin * first[:, 1], sin * first[:, 0] + cos * first[:, 1], height],
        axis=1,
    )
    centre0, centre = first.mean(axis=0), truth[1].mean(axis=0)
    u, _, vt = np.linalg.svd((first - centre0).T @ (truth[1] - centre))
    moved = (turned - centre0) @ (u @ vt) + centre
    slid = np.stack([first, closest_points_on_mesh(truth[1], faces, moved).points])
    observed = np.ones(slid.shape[:2], dtype=bool)
    fitted = fit_rest(slid, faces, observed, [(v, faces) for v in truth])
    before = np.median(np.linalg.norm(slid[1] - truth[1], axis=1)[top]) / edge
    after = np.median(np.linalg.norm(fitted[1] - truth[1], axis=1)[top]) / edge
    # measured: 0.53 edges before, 0.12 after; 0.23 when the rounds stopped at the median
    # vertex's settling (rest_fit.SETTLED_PERCENTILE 50)
    assert after < 0.3 * before, (before, after)


def test_a_frame_without_a_surface_keeps_the_last_correction():
    truth, faces, _ = _turning(3)
    fit = RestFit(truth[0], faces)
    fit.carried = np.full_like(truth[0], 0.01)
    moved = fit.frame(
        truth[1],
        np.ones(len(truth[1]), dtype=bool),
        (np.zeros((0, 3)), np.zeros((0, 3), dtype=int)),
    )
    np.testing.assert_allclose(moved, truth[1] + 0.01)


@pytest.mark.parametrize("stopped", [2, 3])
def test_the_rest_fit_resumes_at_the_first_frame_it_has_not_kept(tmp_path, monkeypatch, stopped):
    truth, faces, _ = _turning(4)
    slid = _twisted(truth, faces, twist=0.08)
    observed = np.ones(truth.shape[:2], dtype=bool)
    meshes = [(v, faces) for v in truth]
    cache = StageCache(tmp_path)
    whole = fit_rest(slid, faces, observed, meshes, cache=cache)
    entries = sorted(
        tmp_path.glob(f"{rest_fit.STAGE}-*.npz"), key=lambda path: path.stat().st_mtime_ns
    )
    assert len(entries) == 3
    for entry in entries[stopped - 1 :]:  # stopped during frame `stopped`
        entry.unlink()
    calls = []
    frame = RestFit.frame
    monkeypatch.setattr(RestFit, "frame", lambda self, *a: calls.append(1) or frame(self, *a))
    resumed = fit_rest(slid, faces, observed, meshes, cache=cache)
    assert len(calls) == 4 - stopped
    np.testing.assert_array_equal(resumed, whole)
