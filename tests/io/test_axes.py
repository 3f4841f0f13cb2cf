"""Output conventions: Z-up to Y-up rotation and the output scale."""

import numpy as np
import pytest

from fourd.animation import AnimatedMesh, MeshSequence
from fourd.errors import InputError
from fourd.io.axes import Z_UP_TO_Y_UP, check_up, scaled, transformed, z_up_to_y_up


def test_z_up_to_y_up_is_a_proper_rotation_taking_z_to_y():
    assert np.allclose(Z_UP_TO_Y_UP @ Z_UP_TO_Y_UP.T, np.eye(3))
    assert np.linalg.det(Z_UP_TO_Y_UP) == pytest.approx(1.0)  # no mirror: windings kept
    up, forward = z_up_to_y_up(np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]))
    assert up.tolist() == [0.0, 1.0, 0.0]  # Z up becomes Y up
    assert forward.tolist() == [0.0, 0.0, -1.0]  # Y (Blender's forward) becomes -Z (glTF's)
    assert z_up_to_y_up(np.ones((2, 4, 3))).shape == (2, 4, 3)


def test_transformed_and_scaled_results():
    rng = np.random.default_rng(1)
    vertices = rng.normal(size=(3, 4, 3))
    anim = AnimatedMesh([[0, 1, 2], [0, 2, 3]], vertices, times=[0.0, 0.5, 1.0], rest=vertices[0])
    assert transformed(anim, np.eye(3)) is anim
    double = scaled(anim, 2.0)
    assert np.allclose(double.vertices, 2 * vertices) and np.allclose(double.rest, 2 * vertices[0])
    assert np.array_equal(double.faces, anim.faces) and np.array_equal(double.times, anim.times)
    assert np.array_equal(double.observed, anim.observed)
    turned = transformed(anim, Z_UP_TO_Y_UP)
    assert np.allclose(turned.vertices[..., 1], vertices[..., 2])
    seq = MeshSequence(((vertices[0], [[0, 1, 2]]), (vertices[1][:3], [[2, 1, 0]])), times=[0, 2])
    half = scaled(seq, 0.5)
    assert np.allclose(half.meshes[1][0], 0.5 * vertices[1][:3])
    assert np.array_equal(half.meshes[1][1], [[2, 1, 0]]) and half.times.tolist() == [0.0, 2.0]


def test_bad_scale_and_up_are_input_errors():
    anim = AnimatedMesh(np.zeros((0, 3), int), np.ones((1, 2, 3)))
    for bad in (0, -1, float("nan"), float("inf"), "big"):
        with pytest.raises(InputError, match="scale must be"):
            scaled(anim, bad)
    assert check_up("Z") == "z"
    with pytest.raises(InputError, match="'y' or 'z'"):
        check_up("x")
