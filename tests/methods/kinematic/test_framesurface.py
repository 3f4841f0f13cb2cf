"""The IMLS surface of one frame's points (the data term)."""

import numpy as np

from fourd.methods import kinematic as K


def test_frame_surface_is_the_signed_distance_near_its_points():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    surface = K.FrameSurface(d, d, bandwidth=0.05)  # unit sphere, outward normals
    q = rng.normal(size=(500, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    for offset in (-0.02, 0.0, 0.03):
        value, gradient, coverage = surface.evaluate(q * (1.0 + offset))
        assert np.abs(value - offset).max() < 0.004
        assert np.einsum("ij,ij->i", gradient, q).min() > 0.98
        assert coverage.min() == 1.0
    value, gradient, coverage = surface.evaluate(q * 2.0)  # far from every point
    assert np.all(coverage == 0) and np.all(value == 0) and np.all(gradient == 0)


def test_the_frame_surface_weights_exp_matches_numpy():
    from fourd.methods.kinematic.framesurface import _exp_into

    x = np.r_[0.0, -1e-300, -np.log(2) / 2, -6.25, -np.random.default_rng(0).uniform(0, 6.25, 5000)]
    out, bits = np.full(len(x) + 1, -1.0), np.empty(len(x) + 1, np.int64)
    _exp_into(x, len(x), out, bits)
    np.testing.assert_allclose(out[:-1], np.exp(x), rtol=4e-16, atol=0)
    assert out[-1] == -1.0  # only the first count values are written


def test_frame_surface_ignores_the_far_side_of_a_thin_part():
    rng = np.random.default_rng(4)
    uv = rng.uniform(-1, 1, size=(20000, 2))
    gap = 0.04  # a slab thinner than the kernel (bandwidth 0.03, cut at 0.075)
    top = np.c_[uv[:10000], np.full(10000, gap / 2)]
    bottom = np.c_[uv[10000:], np.full(10000, -gap / 2)]
    normals = np.r_[np.tile([0, 0, 1.0], (10000, 1)), np.tile([0, 0, -1.0], (10000, 1))]
    surface = K.FrameSurface(np.r_[top, bottom], normals, bandwidth=0.03)
    q = np.c_[rng.uniform(-0.5, 0.5, size=(200, 2)), np.full(200, gap / 2 + 0.005)]
    value, gradient, _ = surface.evaluate(q)
    assert np.abs(value - 0.005).max() < 0.002
    assert gradient[:, 2].min() > 0.99
