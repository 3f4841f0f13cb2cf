"""The 4D MPU implicit of the kinematic method (000_00387fefe94cc850.txt section 3)."""

import numpy as np
import pytest

from fourd.geometry.field import Field4D
from fourd.methods.kinematic.field import SpaceTimeField
from fourd.methods.kinematic.mpu4d import KIND_FEATURE, MPUOptions, fit_mpu4d


def _hypersphere(count, radius, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 4))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return radius * d, d


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


def _moving_sphere(rng, *, frames, count, shift, time_step, bump=0.0):
    """4D points [frames * count, 4] and normals of a unit sphere (radius modulated by
    ``bump * sin(3 x)``) moving ``shift`` along x per frame, frame ``t`` at time
    ``t * time_step``; directions drawn from ``rng``."""
    points, normals = [], []
    for t in range(frames):
        d = rng.normal(size=(count, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        shape = d * (1 + bump * np.sin(3 * d[:, :1]))
        points.append(np.c_[shape + [shift * t, 0.0, 0.0], np.full(count, time_step * t)])
        normals.append(np.c_[d, np.zeros(count)])
    return np.concatenate(points), np.concatenate(normals)


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


def test_space_time_field_is_a_field4d_in_real_time_units():
    points, normals = _hypersphere(3000, 1.0, 5)
    mpu = fit_mpu4d(points, normals, options=MPUOptions(error=1e-3))
    field = SpaceTimeField.single(mpu, time_origin=10.0, time_scale=0.5)
    assert isinstance(field, Field4D)
    x = np.array([[0.0, 0.0, 0.5]])
    t = 10.0 + 0.5 / 0.5  # w = 0.5
    value = field.value(x, t)
    assert abs(value[0] - mpu(np.array([[0, 0, 0.5, 0.5]]))[0]) < 1e-12
    g = field.gradient(x, np.array([t]))
    h = 1e-6
    fd = (field.value(x, t + h) - field.value(x, t - h)) / (2 * h)
    assert abs(fd[0] - g[0, 3]) < 1e-5


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


def test_windowed_fits_cover_the_sequence_with_bounded_memory():
    from fourd.methods.kinematic.field import fit_windows, space_time_points

    rng = np.random.default_rng(8)
    pts, nrm = [], []
    for t in range(6):
        d = rng.normal(size=(800, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts.append(d + [0.02 * t, 0, 0])
        nrm.append(d)
    times = np.arange(6.0)
    stp = space_time_points(pts, nrm, times, delta=0.08, time_origin=0.0, time_unit=1.0)
    field = fit_windows(
        stp,
        times,
        mpu_options=MPUOptions(error=0.01),
        window=2,
        overlap=1,
        time_origin=0.0,
        time_scale=0.08,
    )
    assert len(field.windows) == 3
    for t in times:
        x = pts[int(t)][:50]
        assert np.abs(field.value(x, t)).max() < 0.02
        assert len(field._cache) <= 2
    assert field.fits >= 3


def test_child_point_lists_filtered_from_the_parent_match_a_brute_force_ball_query():
    from fourd.methods.kinematic.mpu4d import _CORNERS, _child_counts, _child_fill

    rng = np.random.default_rng(5)
    X = rng.uniform(-1.0, 1.0, size=(3000, 4))
    centres = np.array([[0.0, 0.0, 0.0, 0.0], [0.3, -0.2, 0.1, 0.0]])
    half, alpha = 0.5, 0.75
    parent_r, child_half = 4.0 * alpha * half, half / 2.0
    child_r = 4.0 * alpha * child_half
    lists = [np.flatnonzero(np.linalg.norm(X - c, axis=1) <= parent_r) for c in centres]
    indptr = np.r_[0, np.cumsum([len(x) for x in lists])].astype(np.int64)
    indices = np.concatenate(lists).astype(np.int64)
    parents = np.array([0, 1], dtype=np.int64)
    counts = np.zeros(32, dtype=np.int64)
    inside = np.zeros(32, dtype=np.int64)
    masks = np.zeros(len(indices), dtype=np.uint16)
    _child_counts(X, indptr, indices, parents, centres, child_half, child_r, counts, inside, masks)
    slot = np.arange(32, dtype=np.int64)
    slot[7] = -1  # a dropped child
    kept = slot >= 0
    out_ptr = np.r_[0, np.cumsum(counts[kept])].astype(np.int64)
    out = np.empty(int(out_ptr[-1]), dtype=np.int64)
    slot[kept] = np.arange(int(kept.sum()))
    _child_fill(indptr, indices, parents, masks, slot, out_ptr, out)
    children = (centres[:, None, :] + child_half * _CORNERS[None]).reshape(-1, 4)
    for k, child in enumerate(children):
        d = X - child
        expect = np.flatnonzero(np.linalg.norm(d, axis=1) <= child_r)
        assert counts[k] == len(expect)
        assert inside[k] == np.sum(np.abs(d).max(axis=1) <= child_half)
        if slot[k] >= 0:
            got = out[out_ptr[slot[k]] : out_ptr[slot[k] + 1]]
            assert np.array_equal(np.sort(got), expect)


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
