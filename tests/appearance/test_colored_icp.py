import numpy as np
import pytest

from fourd.appearance.colored_icp import color_gradients, colored_icp
from fourd.errors import InputError
from fourd.synth.albedo import albedo


def _rotation(axis, degrees):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.deg2rad(degrees)
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


def _skin_plane(count=5000, seed=0):
    rng = np.random.default_rng(seed)
    points = np.column_stack([rng.uniform(-1, 1, (count, 2)), np.zeros(count)])
    box = np.array([[-1.0, -1.0, -0.1], [1.0, 1.0, 0.1]])
    return points, albedo(points, "skin", bounds=box, seed=3)


def test_colour_recovers_a_slide_that_geometry_cannot_see():
    points, colors = _skin_plane()
    shift = np.array([0.04, -0.025, 0.0])
    target = points + shift  # the material (and its colour) slides within the plane
    result = colored_icp(points, colors, target, colors)
    np.testing.assert_allclose(result.transform[:3, 3], shift, atol=2e-3)
    np.testing.assert_allclose(result.transform[:3, :3], np.eye(3), atol=1e-3)
    assert result.converged and result.fitness > 0.95
    assert result.history[-1] < result.history[0]
    geometric = colored_icp(points, colors, target, colors, geometry_weight=1.0)
    assert np.linalg.norm(geometric.transform[:2, 3]) < 0.2 * np.linalg.norm(shift[:2])


def test_rigid_motion_of_a_coloured_surface_is_recovered():
    rng = np.random.default_rng(1)
    direction = rng.normal(size=(6000, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    cap = direction[direction[:, 2] > 0.3]  # a spherical cap: curved, partly constraining
    colors = albedo(cap, "cloth", bounds=np.array([[-1.0] * 3, [1.0] * 3]), seed=0)
    turn = _rotation([0.2, 0.1, 1.0], 6.0)
    shift = np.array([0.02, 0.01, -0.015])
    target = cap @ turn.T + shift
    result = colored_icp(cap, colors, target, colors)
    np.testing.assert_allclose(result.transform[:3, :3], turn, atol=3e-3)
    np.testing.assert_allclose(result.transform[:3, 3], shift, atol=3e-3)
    assert result.rmse < 0.01


def test_gradients_lie_in_the_tangent_plane_and_measure_a_ramp():
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(-1, 1, (800, 2)), np.zeros(800)])
    normals = np.tile([0.0, 0.0, 1.0], (800, 1))
    intensity = 0.3 * points[:, 0] - 0.2 * points[:, 1] + 0.5
    gradient = color_gradients(points, normals, intensity)
    np.testing.assert_allclose(gradient, np.tile([0.3, -0.2, 0.0], (800, 1)), atol=1e-6)


def test_bad_inputs():
    points, colors = _skin_plane(100)
    with pytest.raises(InputError, match="source_colors"):
        colored_icp(points, colors[:5], points, colors)
    with pytest.raises(InputError, match="geometry_weight"):
        colored_icp(points, colors, points, colors, geometry_weight=0.0)
    with pytest.raises(InputError, match="fewer than 6 matches"):
        colored_icp(points, colors, points + 10.0, colors)
