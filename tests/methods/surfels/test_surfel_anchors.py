"""The video's anchors in eq. (3): a slide along a featureless surface, which the data term
cannot see, is recovered from them; an anchor far off is cut off."""

import numpy as np
import pytest

from fourd.methods.surfels import (
    AnchorData,
    Forward,
    GaussNewtonOptions,
    Weights,
    anchor_term,
    build_topology,
    frame_data,
    free_unknowns,
    gauss_newton,
    layout,
    pair_anchors,
    surfel_state,
)

SLIDE = np.array([0.08, 0.03, 0.0])


def _sliding_plane(anchor_weight):
    """Two frames of the plane z = 0 (the same points: a slide along it looks like nothing),
    the surfels of frame 1 starting where frame 0's are, anchors saying they moved by
    ``SLIDE``; returns the surfels' mean move and the frame-0 positions."""
    rng = np.random.default_rng(0)
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 15), np.linspace(-1, 1, 15)), -1).reshape(-1, 2)
    surfels = np.c_[grid, np.zeros(len(grid))]
    normals = np.tile([0.0, 0.0, 1.0], (len(grid), 1))
    state = surfel_state(np.stack([surfels, surfels]), np.stack([normals, normals]))
    topology = build_topology(state.positions, 0.3, max_stretch=None)
    points = np.c_[rng.uniform(-1.2, 1.2, (2000, 2)), rng.normal(scale=0.005, size=2000)]
    sources = surfels[rng.choice(len(surfels), 60, replace=False)] + np.r_[
        rng.normal(scale=0.03, size=(60, 2)).T, np.zeros((1, 60))
    ].T
    tracked = Forward(sources, sources + SLIDE, np.full(60, 0.8))
    data = frame_data([points, points], normals=[np.tile([0, 0, 1.0], (2000, 1))] * 2,
                      anchors=pair_anchors([tracked]))
    noise = 0.01
    weights = Weights(match=1 / noise**2, smooth_position=0.5 / noise**2, rigid=1 / noise**2,
                      anchor=anchor_weight / noise**2)
    moving = np.zeros((2, len(surfels)), dtype=bool)
    moving[1] = True  # frame 0 is held
    result = gauss_newton(
        state, topology, data, weights, options=GaussNewtonOptions(iterations=8),
        free=free_unknowns(layout(state), moving),
    )
    moved = result.state.positions[1] - result.state.positions[0]
    return moved, surfels


def test_anchors_recover_a_slide_the_data_cannot_see():
    moved, surfels = _sliding_plane(1.0)
    inner = np.all(np.abs(surfels[:, :2]) < 0.75, axis=1)
    # measured: the inner surfels moved within 0.002 of the anchors' slide (0.085 long)
    assert np.abs(moved[inner] - SLIDE).max() < 0.01
    # and stayed on the plane
    assert np.abs(moved[:, 2]).max() < 0.01


def test_without_anchors_the_slide_is_not_seen():
    moved, _ = _sliding_plane(0.0)
    assert np.linalg.norm(moved, axis=1).max() < 0.01


def test_pair_anchors_index_each_pair_by_its_first_frame():
    one = Forward(np.zeros((2, 3)), np.ones((2, 3)), np.array([0.5, 1.0]))
    two = Forward(np.ones((1, 3)), np.zeros((1, 3)), np.array([0.25]))
    anchors = pair_anchors([one, None, two])
    assert anchors.frames.tolist() == [0, 0, 2]
    assert anchors.weights.tolist() == [0.5, 1.0, 0.25]
    assert anchors.shifted(1).frames.tolist() == [1, 1, 3]
    back = two.reversed()
    assert np.array_equal(back.source, two.target) and np.array_equal(back.target, two.source)
    assert pair_anchors([None, Forward(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))]) is None


def test_anchor_data_checks_its_shapes():
    with pytest.raises(ValueError, match="sources and targets"):
        AnchorData(np.zeros(2, dtype=np.int64), np.zeros((2, 3)), np.zeros((3, 3)), np.ones(2))
    with pytest.raises(ValueError, match="weights"):
        AnchorData(np.zeros(1, dtype=np.int64), np.zeros((1, 3)), np.zeros((1, 3)), -np.ones(1))


def test_an_anchor_far_from_its_surfels_move_adds_a_constant_and_no_pull():
    positions = np.array([[[0.0, 0, 0], [1, 0, 0]], [[0.0, 0, 0], [1, 0, 0]]])
    state = surfel_state(positions, np.tile([0.0, 0, 1], (2, 2, 1)))
    # the first anchor moved 0.1 (inside the reach 0.5), the second 2.0 (outside); the third
    # starts 2.5 from every surfel
    anchors = AnchorData(
        np.zeros(3, dtype=np.int64),
        np.array([[0.0, 0, 0], [1, 0, 0], [3.5, 0, 0]]),
        np.array([[0.1, 0, 0], [1, 2, 0], [3.5, 1, 0]]),
        np.array([1.0, 0.5, 1.0]),
    )
    at = anchor_term(state, anchors, 2.0, 0.5)
    assert at.value == pytest.approx(2.0 * 0.1**2 + 2.0 * 0.5 * 0.5**2)
    assert np.count_nonzero(at.jacobian[3:].toarray()) == 0
    assert at.gradient[layout(state).position(1, 0)] == pytest.approx(2 * 2.0 * -0.1)
