"""Rigid point-to-plane ICP recovers a known rigid motion (or a translation alone), also
with outliers among the source points."""

import numpy as np
import pytest

from fourd.geometry.icp import _rotation, rigid_icp


def _bumpy_blob(count, rng):
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radius = 1.0 + 0.1 * np.sin(3 * directions[:, 0]) * np.cos(2 * directions[:, 1])
    return directions * radius[:, None]


def _normals(points):
    from fourd.geometry.normals import estimate_normals

    return estimate_normals(points).normals


def test_a_known_rigid_motion_is_recovered():
    rng = np.random.default_rng(0)
    target = _bumpy_blob(6000, rng)
    normals = _normals(target)
    turn = _rotation(np.array([0.05, -0.08, 0.1]))
    shift = np.array([0.04, -0.02, 0.03])
    # the source: other samples of the same surface, moved away by the inverse motion
    source = (_bumpy_blob(3000, rng) - shift) @ turn
    fit = rigid_icp(source, target, normals, trim=100)
    assert np.allclose(fit.rotation, turn, atol=5e-3)
    assert np.allclose(fit.translation, shift, atol=5e-3)
    assert fit.rms < 0.01


def test_outliers_are_trimmed():
    rng = np.random.default_rng(1)
    target = _bumpy_blob(6000, rng)
    normals = _normals(target)
    turn = _rotation(np.array([0.0, 0.06, -0.04]))
    source = _bumpy_blob(3000, rng) @ turn
    noisy = np.concatenate([source, rng.uniform(-3, 3, (300, 3))])
    fit = rigid_icp(noisy, target, normals)  # the 85th percentile of the distances
    assert np.allclose(fit.rotation, turn, atol=1e-2)
    assert np.linalg.norm(fit.translation) < 1e-2


def test_a_translation_alone_when_asked():
    rng = np.random.default_rng(2)
    target = _bumpy_blob(6000, rng)
    normals = _normals(target)
    shift = np.array([0.03, 0.01, -0.02])
    source = _bumpy_blob(3000, rng) @ _rotation(np.array([0.0, 0.0, 0.05])).T - shift
    fit = rigid_icp(source, target, normals, trim=100, rotate=False)
    assert np.array_equal(fit.rotation, np.eye(3))
    assert np.allclose(fit.translation, shift, atol=1e-2)


def test_a_rotation_the_surface_does_not_determine_is_not_applied():
    # a spheroid seen from one side, squashed: its spin about the axis is free
    rng = np.random.default_rng(3)
    view = np.array([1.0, 0.4, 0.5]) / np.linalg.norm([1.0, 0.4, 0.5])

    def spheroid(radii, count):
        points = rng.normal(size=(count, 3))
        points *= radii / np.linalg.norm(points, axis=1, keepdims=True)
        normals = points / np.square(radii)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        seen = normals @ view > 0.2
        return points[seen] + rng.normal(scale=0.004, size=(seen.sum(), 3)), normals[seen]

    (source, source_normals), (target, normals) = (
        spheroid([1, 1, 0.8], 4000),
        spheroid([1.06, 1.06, 0.72], 8000),
    )
    free = rigid_icp(source, target, normals, source_normals=source_normals)
    kept = rigid_icp(source, target, normals, source_normals=source_normals, rotation_evidence=0.1)
    assert np.degrees(np.arccos((np.trace(free.rotation) - 1) / 2)) > 10  # measured: 25
    assert np.array_equal(kept.rotation, np.eye(3))
    # max_turn alone refuses only a turn above it
    capped = rigid_icp(source, target, normals, source_normals=source_normals, max_turn=5)
    allowed = rigid_icp(source, target, normals, source_normals=source_normals, max_turn=90)
    assert np.array_equal(capped.rotation, np.eye(3))
    assert np.array_equal(allowed.rotation, free.rotation)
    # a rotation the surface does determine is kept
    target = _bumpy_blob(6000, rng)
    turn = _rotation(np.array([0.05, -0.08, 0.1]))
    fit = rigid_icp(_bumpy_blob(3000, rng) @ turn, target, _normals(target), rotation_evidence=0.1)
    assert np.allclose(fit.rotation, turn, atol=1e-2)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="source"):
        rigid_icp(np.zeros((2, 3)), np.zeros((5, 3)), np.ones((5, 3)))
    with pytest.raises(ValueError, match="trim"):
        rigid_icp(np.zeros((5, 3)), np.zeros((5, 3)), np.ones((5, 3)), trim=0)
    with pytest.raises(ValueError, match="max_turn"):
        rigid_icp(np.zeros((5, 3)), np.zeros((5, 3)), np.ones((5, 3)), max_turn=-1)
    with pytest.raises(ValueError, match="rotation_evidence"):
        rigid_icp(np.zeros((5, 3)), np.zeros((5, 3)), np.ones((5, 3)), rotation_evidence=1)
