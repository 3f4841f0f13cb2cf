"""The rigid prediction of the sliding's initial guess."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation


def test_a_global_rigid_motion_fitted_to_a_sample_moves_every_vertex():
    from fourd.methods.kinematic.rigid import rigid_prediction

    rng = np.random.default_rng(3)
    positions = rng.normal(size=(3000, 3))
    axes = np.array([1.0, 0.6, 0.3])  # an ellipsoid: no motion slides it along itself
    positions = positions / np.linalg.norm(positions, axis=1, keepdims=True) * axes
    # point-to-plane residuals of a small rigid motion, measured against its planes
    rotation = Rotation.from_rotvec([0.02, -0.01, 0.015]).as_matrix()
    translation = np.array([0.01, 0.03, -0.02])
    moved = positions @ rotation.T + translation
    normals = (positions / axes**2) @ rotation.T
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    residuals = np.einsum("ij,ij->i", normals, positions - moved)
    sample = np.linspace(0, len(positions) - 1, 400).astype(np.int64)
    predicted = rigid_prediction(
        positions, normals[sample], residuals[sample], sample=sample, regularization=0.0
    )
    full = rigid_prediction(positions, normals, residuals, regularization=0.0)
    # one linearised step: second order in the motion, the same from the sample as from all
    assert np.abs(predicted - moved).max() < 1e-3  # the motion: up to 0.046
    assert np.abs(predicted - full).max() < 2e-4
    with pytest.raises(ValueError):
        rigid_prediction(positions, normals, residuals, sample=sample, neighbours=8)
