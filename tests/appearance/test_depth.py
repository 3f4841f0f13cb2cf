import numpy as np

from fourd.appearance.cameras import look_at, project
from fourd.appearance.depth import frame_view, lift, splat_depth, visible_points


def _camera():
    return look_at("c", [0.3, 0.2, 4.0], [0, 0, 0], [0, 1, 0], focal=60, width=48, height=48)


def _plane(z=0.0, count=90, half=1.0, noise=0.0, seed=0, tilt=0.0):
    g = np.linspace(-half, half, count)
    x, y = np.meshgrid(g, g)
    points = np.stack([x.ravel(), y.ravel(), z + tilt * x.ravel()], axis=1)
    points[:, 2] += np.random.default_rng(seed).normal(scale=noise, size=len(points))
    return points


def test_lift_puts_pixels_back_on_a_tilted_plane():
    cam = _camera()
    plane = _plane(tilt=0.4)
    view = frame_view(cam, plane, tolerance=0.05)
    truth = np.array([[0.1, -0.2, 0.04], [0.5, 0.5, 0.2], [-0.6, 0.3, -0.24]])
    uv, _ = project(cam, truth)
    np.testing.assert_allclose(lift(view, uv, tolerance=0.05), truth, atol=1e-9)


def test_lift_averages_the_noise():
    cam = _camera()
    sigma = 0.004
    view = frame_view(cam, _plane(noise=sigma), tolerance=0.05)
    rng = np.random.default_rng(1)
    uv = rng.uniform(10, 38, size=(300, 2))
    lifted = lift(view, uv, tolerance=0.05)
    assert np.isfinite(lifted).all()
    assert np.std(lifted[:, 2]) < 0.6 * sigma  # on the plane closer than a single point


def test_lift_refuses_holes_and_depth_edges():
    cam = _camera()
    near = _plane(z=0.5, half=0.6, count=17)  # about one point per pixel, as scans are
    near = near[near[:, 0] > 0]  # a step: the right half is nearer
    points = np.concatenate([_plane(count=30), near])
    view = frame_view(cam, points, tolerance=0.05)
    on_edge, _ = project(cam, [[0.0, 0.0, 0.5]])
    outside = np.array([[0.0, 0.0], [47.0, 2.0]])  # beyond the plane's silhouette
    lifted = lift(view, np.concatenate([on_edge, outside]), tolerance=0.05)
    assert np.isnan(lifted).all()
    inside, _ = project(cam, [[0.3, 0.0, 0.5]])
    np.testing.assert_allclose(lift(view, inside, tolerance=0.05), [[0.3, 0.0, 0.5]], atol=1e-9)


def test_points_behind_others_are_not_seen():
    cam = _camera()
    front = _plane(z=0.5, count=60, half=0.6)
    back = _plane(z=-0.5, count=60, half=0.6)
    depth = splat_depth(cam, np.concatenate([front, back]))
    seen = visible_points(cam, depth, np.concatenate([front, back]), tolerance=0.05)
    assert seen[: len(front)].mean() > 0.99 and seen[len(front) :].mean() < 0.2
    assert np.isinf(depth.depth[0, 0]) and depth.index[0, 0] == -1
