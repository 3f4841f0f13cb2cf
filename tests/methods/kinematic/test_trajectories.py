"""Temporal smoothing of the vertex trajectories."""

import numpy as np

from fourd.methods import kinematic as K


def test_smooth_trajectories_keeps_linear_motion_and_the_end_frames():
    times = np.array([0.0, 1.0, 1.5, 3.0, 4.0])
    rng = np.random.default_rng(5)
    start, velocity = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    linear = start[None] + times[:, None, None] * velocity[None]
    assert np.allclose(K.smooth_trajectories(linear, times, 2), linear)
    noisy = linear + 0.1 * rng.normal(size=linear.shape)
    smoothed = K.smooth_trajectories(noisy, times, 1)
    assert np.array_equal(smoothed[[0, -1]], noisy[[0, -1]])
    inner = slice(1, -1)
    assert (
        np.abs(smoothed[inner] - linear[inner]).mean() < np.abs(noisy[inner] - linear[inner]).mean()
    )
    assert np.array_equal(K.smooth_trajectories(noisy, times, 0), noisy)


def test_smooth_trajectories_with_a_motion_threshold_leaves_an_acceleration_alone():
    # a noisy grid, its last quarter accelerating steadily (a kick): the plain filter cuts
    # the accelerating part's trajectory by a quarter of its second difference, the
    # motion-aware one keeps it there and still takes out the still part's noise
    u, v = np.meshgrid(np.linspace(0.0, 1.0, 24), np.linspace(0.0, 1.0, 24))
    grid = np.c_[u.ravel(), v.ravel(), np.zeros(u.size)]
    times = np.arange(7.0)
    truth = np.repeat(grid[None], len(times), axis=0)
    kicking = grid[:, 0] > 0.75
    truth[:, kicking, 2] = 0.5 * (times[:, None] - 3.0) ** 2
    noisy = truth + 0.01 * np.random.default_rng(6).normal(size=truth.shape)
    threshold = K.Options().smoothing_motion
    plain = K.smooth_trajectories(noisy, times, 1)
    aware = K.smooth_trajectories(noisy, times, 1, motion_threshold=threshold)

    def error(x, mask):
        return np.linalg.norm(x[1:-1, mask] - truth[1:-1, mask], axis=2).mean()

    inside, still = grid[:, 0] > 0.85, grid[:, 0] < 0.6
    assert error(plain, inside) > 0.2
    assert error(aware, inside) < 0.03
    assert error(aware, still) < 0.8 * error(noisy, still)
    assert error(aware, still) < 1.1 * error(plain, still)
    assert np.array_equal(aware[[0, -1]], noisy[[0, -1]])
    # a region jumping off in one frame and back in the next (a glitch) is smoothed as
    # by the plain filter
    glitch = noisy.copy()
    glitch[3, grid[:, 0] < 0.3, 2] += 0.5
    plain = K.smooth_trajectories(glitch, times, 1)
    aware = K.smooth_trajectories(glitch, times, 1, motion_threshold=threshold)
    glitched = grid[:, 0] < 0.2
    worst = [np.abs(x[3, glitched, 2] - truth[3, glitched, 2]).mean() for x in (plain, aware)]
    assert worst[1] < 1.1 * worst[0] < 0.3
