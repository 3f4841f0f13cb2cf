"""Material fields: validation, the one-field interface, files."""

import numpy as np
import pytest
from deform_shapes import tube

from fourd.deform import Material, from_shearing, load_material, save_material, uniform_material
from fourd.errors import InputError
from fourd.geometry.meshes import face_adjacency


def test_bending_from_shearing_is_the_mean_of_the_two_faces():
    _, faces, _, _ = tube(rings=5)
    shearing = np.linspace(0.1, 1.0, len(faces))
    material = from_shearing(faces, shearing)
    pairs, _ = face_adjacency(faces)
    assert np.allclose(material.bending, 0.5 * (shearing[pairs[:, 0]] + shearing[pairs[:, 1]]))


def test_a_material_round_trips_through_its_file(tmp_path):
    _, faces, _, _ = tube(rings=5)
    material = uniform_material(faces, 0.5)
    save_material(material, tmp_path / "m.npz")
    back = load_material(tmp_path / "m.npz")
    assert np.array_equal(back.bending, material.bending) and np.array_equal(back.shearing, material.shearing)
    (tmp_path / "bad.npz").write_bytes(b"nonsense")
    with pytest.raises(InputError, match="bad.npz"):
        load_material(tmp_path / "bad.npz")


def test_stiffness_must_be_positive_and_well_shaped():
    with pytest.raises(InputError, match="positive"):
        Material(np.array([1.0, 0.0]), np.ones(3))
    with pytest.raises(InputError, match=r"\[E, 3\]"):
        Material(np.ones((4, 2)), np.ones(3))
