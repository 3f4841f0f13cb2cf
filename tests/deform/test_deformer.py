"""Material-aware deformation on a tube: the thesis' bar examples (Figures 2.4, 2.5, 2.10)."""

import numpy as np
import pytest
from deform_shapes import tube
from scipy.spatial.transform import Rotation

from fourd.deform import (
    Deformer,
    Material,
    deformation_gradients,
    from_shearing,
    rotation_about,
    uniform_material,
)
from fourd.errors import InputError
from fourd.geometry.meshes import face_adjacency
from fourd.geometry.rotations import best_rotations

LENGTH = 4.0


def _face_rotvecs(rest, posed, faces):
    gradients = deformation_gradients(rest, posed, faces)
    return Rotation.from_matrix(best_rotations(np.transpose(gradients, (0, 2, 1)))).as_rotvec()


def _end_transforms(end_rotation, caps=12):
    return np.stack([np.eye(3)] * caps + [end_rotation] * caps)


def _middle(x):
    return (x > LENGTH / 3) & (x < 2 * LENGTH / 3)


def test_identity_anchors_reproduce_the_rest_mesh():
    vertices, faces, start, end = tube()
    deformer = Deformer(vertices, faces, anchors=np.r_[start, end])
    assert np.allclose(deformer.pose(), vertices, atol=1e-10)


def test_one_rotation_of_every_anchor_moves_the_mesh_rigidly():
    vertices, faces, start, end = tube()
    turn = rotation_about([1, 2, 3], 0.7)
    deformer = Deformer(vertices, faces, anchors=np.r_[start, end])
    posed = deformer.pose(np.stack([turn] * 24))
    pivot = vertices[deformer.fixed[0]]
    assert np.allclose(posed, (vertices - pivot) @ turn.T + pivot, atol=1e-7)


def test_a_uniform_bar_twists_uniformly_and_a_stiff_middle_stays_rigid():
    vertices, faces, start, end = tube()
    side = np.arange(len(faces) - 24)
    x = vertices[faces[side]].mean(axis=1)[:, 0]
    twist = rotation_about([1, 0, 0], 1.2)
    uniform = Deformer(vertices, faces, anchors=np.r_[start, end])
    angle = _face_rotvecs(vertices, uniform.pose(_end_transforms(twist)), faces)[side, 0]
    inner = (x > 0.5) & (x < LENGTH - 0.5)  # the rings next to the caps carry an end effect
    slope, offset = np.polyfit(x[inner], angle[inner], 1)
    assert np.abs(np.polyval([slope, offset], x[inner]) - angle[inner]).max() < 0.02
    first, second = (np.polyfit(x[half], angle[half], 1)[0] for half in (x < LENGTH / 2, x >= LENGTH / 2))
    assert first == pytest.approx(second, rel=0.05)
    assert np.ptp(angle) > 0.7 * 1.2  # most of the twist along the side, some in the caps
    stiff = np.where(_middle(vertices[faces].mean(axis=1)[:, 0]), 1.0, 0.01)
    deformer = Deformer(vertices, faces, from_shearing(faces, stiff), anchors=np.r_[start, end])
    angle = _face_rotvecs(vertices, deformer.pose(_end_transforms(twist)), faces)[side, 0]
    middle = _middle(x) & (np.abs(x - LENGTH / 2) < LENGTH / 6 - 0.2)
    assert np.ptp(angle[middle]) < 0.1 * 1.2  # the middle third turns as one piece
    assert np.ptp(angle) > 0.6 * 1.2  # the flexible ends take the twist


def test_an_anisotropic_middle_bends_but_does_not_twist():
    vertices, faces, start, end = tube()
    pairs, _ = face_adjacency(faces)
    centres = vertices[faces].mean(axis=1)[:, 0]
    in_middle = _middle(0.5 * (centres[pairs[:, 0]] + centres[pairs[:, 1]]))
    bending = np.ones((len(pairs), 3))
    bending[:, 0] = np.where(in_middle, 1.0, 0.01)  # twist (about x): stiff middle
    bending[:, 2] = np.where(in_middle, 0.01, 1.0)  # bend (about z): flexible middle
    material = Material(bending, np.ones(len(faces)))
    deformer = Deformer(vertices, faces, material, anchors=np.r_[start, end])
    side = np.arange(len(faces) - 24)
    x = centres[side]
    core = _middle(x) & (np.abs(x - LENGTH / 2) < LENGTH / 6 - 0.2)
    twisted = _face_rotvecs(vertices, deformer.pose(_end_transforms(rotation_about([1, 0, 0], 1.0))), faces)
    assert np.ptp(twisted[side][core, 0]) < 0.1
    bent = _face_rotvecs(vertices, deformer.pose(_end_transforms(rotation_about([0, 0, 1], 1.0))), faces)
    assert np.ptp(bent[side][core, 2]) > 0.6  # the bend happens in the middle (uniform: 0.23)
    outer = x < LENGTH / 3 - 0.2
    assert np.ptp(bent[side][outer, 2]) < 0.1


def test_dragging_a_vertex_finds_the_anchor_rotation():
    vertices, faces, start, end = tube()
    tip, ring = len(vertices) - 1, np.arange(12)
    truth = Deformer(vertices, faces, anchors=np.r_[start, end], fixed=ring)
    posed = truth.pose(_end_transforms(rotation_about([0, 0, 1], 0.5)))
    for search in ("binary", "parabola"):
        deformer = Deformer(vertices, faces, anchors=start, fixed=ring, handles=[tip], search=search)
        result = deformer.pose(positions=[posed[tip]], axes=[[0, 0, 1]])
        assert deformer.angles[0] == pytest.approx(0.5, abs=0.1)
        assert np.linalg.norm(result[tip] - posed[tip]) < 0.01
        assert np.abs(result - posed).max() < 0.05 * LENGTH


def test_bad_anchors_and_transforms_are_refused():
    vertices, faces, start, end = tube()
    with pytest.raises(InputError, match="anchor"):
        Deformer(vertices, faces, anchors=[])
    deformer = Deformer(vertices, faces, anchors=[start[0], end[0]])
    with pytest.raises(InputError, match="uniform scale"):
        deformer.pose(np.stack([np.eye(3), np.diag([1.0, 2.0, 1.0])]))
    with pytest.raises(InputError, match="another mesh"):
        Deformer(vertices, faces, uniform_material(faces[:-1]), anchors=[0])
