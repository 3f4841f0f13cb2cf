"""Stiffness learned from example poses (thesis 2.7) finds a known material's stiff region."""

import numpy as np
from deform_shapes import tube

from fourd.deform import Deformer, from_shearing, learn_material, rotation_about
from fourd.geometry.meshes import face_adjacency


def test_poses_made_by_a_stiff_middle_teach_a_stiff_middle():
    vertices, faces, start, end = tube()
    x = vertices[faces].mean(axis=1)[:, 0]
    middle = (x > 4 / 3) & (x < 8 / 3)
    truth = from_shearing(faces, np.where(middle, 1.0, 0.02))
    deformer = Deformer(vertices, faces, truth, anchors=np.r_[start, end])
    poses = [
        deformer.pose(np.stack([np.eye(3)] * 12 + [rotation_about(axis, angle)] * 12))
        for axis, angle in (([1, 0, 0], 0.8), ([0, 0, 1], 0.6), ([0, 1, 0], -0.7), ([1, 1, 0], 0.5))
    ]
    learned = learn_material(vertices, np.stack(poses), faces)
    pairs, _ = face_adjacency(faces)
    edge_middle = middle[pairs[:, 0]] & middle[pairs[:, 1]]
    edge_side = ~middle[pairs[:, 0]] & ~middle[pairs[:, 1]]
    assert np.median(learned.bending[edge_middle]) > np.median(learned.bending[edge_side]) + 0.2
    assert np.median(learned.shearing[middle]) > np.median(learned.shearing[~middle])
    assert learned.bending.min() > 0 and learned.bending.max() <= 1.05 + 1e-12


def test_the_rest_pose_alone_learns_a_uniform_material():
    vertices, faces, _, _ = tube(rings=6)
    learned = learn_material(vertices, vertices[None], faces)
    assert np.allclose(learned.bending, 1.0) and np.allclose(learned.shearing, 1.0)
