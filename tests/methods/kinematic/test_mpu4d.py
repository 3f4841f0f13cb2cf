"""The 4D MPU implicit of the kinematic method (000_00387fefe94cc850.txt section 3)."""

import numpy as np
import pytest
from kinematic_shapes import _hypersphere, _moving_sphere

from fourd.methods.kinematic.mpu4d import MPUOptions, fit_mpu4d
from fourd.methods.kinematic.mpu_fit import KIND_FEATURE


def test_a_4d_quadric_fitted_to_points_on_a_known_4d_quadric_reproduces_it():
    points, normals = _hypersphere(4000, 1.0, 0)
    q, _ = _hypersphere(2000, 1.0, 1)
    rng = np.random.default_rng(2)
    radii = 1.0 + rng.choice([-1.0, 1.0], size=len(q)) * rng.uniform(0.02, 0.1, size=len(q))
    # one generic 4D quadric (the normals cover the whole sphere) at a loose error ...
    coarse = fit_mpu4d(points, normals, options=MPUOptions(error=0.1))
    assert coarse.stats.leaves == 1 and coarse.stats.generic == 1
    on, grads = coarse.evaluate(q)
    assert np.abs(on).max() < 5e-3
    assert np.min(np.einsum("ij,ij->i", grads, q) / np.linalg.norm(grads, axis=1)) > 0.999
    values, _ = coarse.evaluate(q * radii[:, None])
    assert np.all(np.sign(values) == np.sign(radii - 1.0))
    # ... and low-variate quadrics over the tangent spaces at a tight one
    fine = fit_mpu4d(points, normals, options=MPUOptions(error=1e-4))
    assert fine.stats.leaves > 100 and fine.stats.lowvariate == fine.stats.leaves
    on, grads = fine.evaluate(q)
    assert np.abs(on).max() < 5e-4
    assert np.min(np.einsum("ij,ij->i", grads, q) / np.linalg.norm(grads, axis=1)) > 0.999
    values, _ = fine.evaluate(q * radii[:, None])
    assert np.all(np.sign(values) == np.sign(radii - 1.0))


def test_a_moving_plane_is_reproduced_with_its_normal_velocity():
    rng = np.random.default_rng(3)
    # plane z = 0.3 w + 0.2 x^2 (a parabolic cylinder moving along z over time w)
    xyw = rng.uniform(-1, 1, size=(6000, 3))
    z = 0.3 * xyw[:, 2] + 0.2 * xyw[:, 0] ** 2
    points = np.c_[xyw[:, 0], xyw[:, 1], z, xyw[:, 2]]
    normals = np.c_[-0.4 * xyw[:, 0], np.zeros(6000), np.ones(6000), np.zeros(6000)]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    mpu = fit_mpu4d(points, normals, options=MPUOptions(error=1e-3))
    q = rng.uniform(-0.6, 0.6, size=(500, 3))
    zq = 0.3 * q[:, 2] + 0.2 * q[:, 0] ** 2
    values, grads = mpu.evaluate(np.c_[q[:, 0], q[:, 1], zq, q[:, 2]])
    assert np.abs(values).max() < 2e-3
    # f grows along +z (the outward side) and dz/dw = 0.3 on the surface: f_w / f_z = -0.3
    assert grads[:, 2].min() > 0
    assert np.abs(grads[:, 3] / grads[:, 2] + 0.3).max() < 0.03


def test_values_and_gradients_agree_with_finite_differences():
    rng = np.random.default_rng(4)
    pts, nrm = _moving_sphere(rng, frames=6, count=1500, shift=0.02, time_step=0.05, bump=0.1)
    mpu = fit_mpu4d(pts, nrm, options=MPUOptions(error=0.01))
    q = pts[::17] + rng.normal(scale=0.01, size=(len(pts[::17]), 4))
    values, grads = mpu.evaluate(q)
    covered = np.abs(values) < 0.5 * mpu.outside
    h = 1e-6
    for axis in range(4):
        e = np.zeros(4)
        e[axis] = h
        fd = (mpu(q + e) - mpu(q - e)) / (2 * h)
        assert np.abs(fd - grads[:, axis])[covered].max() < 1e-4 * (
            1 + np.abs(grads[:, axis]).max()
        )


def test_sharp_edges_use_boolean_combinations_of_clustered_pieces():
    rng = np.random.default_rng(6)
    # a static wedge (two half-planes meeting at a right-angled convex edge) over time
    a = rng.uniform(0, 1, size=(4000, 3))
    face1 = np.c_[a[:, 0], a[:, 1], np.zeros(4000), a[:, 2]]  # z = 0, normal -z ... outward -z
    face2 = np.c_[np.zeros(4000), a[:, 1], a[:, 0], a[:, 2]]  # x = 0, outward -x
    points = np.r_[face1, face2]
    normals = np.r_[np.tile([0, 0, -1.0, 0], (4000, 1)), np.tile([-1.0, 0, 0, 0], (4000, 1))]
    mpu = fit_mpu4d(points, normals, options=MPUOptions(error=2e-3, min_points=30))
    assert np.any(mpu.leaf_kind == KIND_FEATURE)
    q = np.c_[rng.uniform(0.005, 0.03, size=(300, 2)), rng.uniform(0.3, 0.7, size=(300, 2))]
    corner = np.c_[q[:, 0], q[:, 2], q[:, 1], q[:, 3]]  # inside the wedge: x > 0 and z > 0
    values, _ = mpu.evaluate(corner)
    depth = np.minimum(q[:, 0], q[:, 1])
    assert np.mean(values < 0) > 0.9
    assert np.median(np.abs(values + depth)) < 0.005


def test_options_are_validated():
    with pytest.raises(ValueError):
        MPUOptions(error=0.0)
    with pytest.raises(ValueError):
        MPUOptions(error=0.1, min_points=5)
    with pytest.raises(ValueError):
        fit_mpu4d(np.zeros((10, 3)), np.zeros((10, 3)), options=MPUOptions(error=0.1))


def test_evaluation_on_a_time_slice_matches_the_tree_descent():
    # a sphere moving along x over 8 frames; many queries at one time use the slice's leaf
    # grids, a few at a time descend the tree: both must give the same f and grad f
    import fourd.methods.kinematic.mpu4d as mpu4d

    rng = np.random.default_rng(0)
    points, normals = _moving_sphere(rng, frames=8, count=3000, shift=0.05, time_step=0.1)
    mpu = fit_mpu4d(points, normals, options=MPUOptions(0.005))
    q = rng.normal(size=(2000, 3)) * 0.8
    for w in (0.0, 0.33, 0.7, 5.0):
        Q = np.c_[q, np.full(len(q), w)]
        slice_f, slice_g = mpu.evaluate(Q)
        step = mpu4d.SLICE_MIN_QUERIES - 1
        tree = [mpu.evaluate(Q[i : i + step]) for i in range(0, len(Q), step)]
        tree_f = np.concatenate([f for f, _ in tree])
        tree_g = np.concatenate([g for _, g in tree])
        assert np.abs(slice_f - tree_f).max() < 1e-12
        assert np.abs(slice_g - tree_g).max() < 1e-10
        if w == 5.0:  # beyond every support
            assert np.all(slice_f == mpu.outside)
        else:
            assert np.mean(slice_f == mpu.outside) < 0.5
    assert len(mpu._slices) <= mpu4d.SLICE_CACHE
