"""The colours' guide in eq. (3): a slide of a printed plane along itself, which the data term
cannot see, is found by the per-surfel Lucas-Kanade and recovered by the optimisation, also
from reference colours carried from another frame; a plane of one colour guides nothing."""

import dataclasses

import numpy as np
import pytest

from fourd.methods.surfels import (
    GaussNewtonOptions,
    GuideData,
    GuideSettings,
    Weights,
    build_topology,
    color_guides,
    frame_data,
    free_unknowns,
    gauss_newton,
    layout,
    reference_colors,
    surfel_state,
)

SLIDE = np.array([0.08, 0.03, 0.0])
SPACING = 1 / 7  # the surfels' grid


def _print(points):
    """A colour print on the plane: three channels, each a wave of another direction."""
    k = 2 * np.pi / 0.8
    x, y = points[:, 0], points[:, 1]
    return 0.5 + 0.3 * np.c_[np.sin(k * x), np.sin(k * y), np.sin(k * (x - y) + 1.0)]


def _plane(rng):
    """Surfels on a grid of the plane z = 0 (positions, normals) and a noisy scan of it
    (points, their normals)."""
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 15), np.linspace(-1, 1, 15)), -1).reshape(-1, 2)
    surfels = np.c_[grid, np.zeros(len(grid))]
    normals = np.tile([0.0, 0.0, 1.0], (len(grid), 1))
    points = np.c_[rng.uniform(-1.2, 1.2, (20000, 2)), rng.normal(scale=0.002, size=20000)]
    return surfels, normals, points, np.tile([0.0, 0.0, 1.0], (len(points), 1))


def _slid_plane(printed=True):
    """Two frames of the plane z = 0 scanned at the same points, the print slid by ``SLIDE``
    in frame 1; the surfels of both frames on one grid (they did not follow the slide)."""
    rng = np.random.default_rng(0)
    surfels, normals, points, point_normals = _plane(rng)
    state = surfel_state(np.stack([surfels, surfels]), np.stack([normals, normals]))
    colors = [_print(points), _print(points - SLIDE)] if printed else [np.full((len(points), 3), 0.6)] * 2
    colors = [np.clip(c + rng.normal(scale=0.01, size=c.shape), 0, 1) for c in colors]
    guides = color_guides(
        state, np.ones((2, len(surfels)), dtype=bool), [points, points], [point_normals] * 2,
        colors, GuideSettings(radius=3 * SPACING, scale=0.5 * SPACING),
    )
    return state, points, guides


def test_the_guides_find_the_slide_of_the_print():
    state, _, guides = _slid_plane()
    inner = np.all(np.abs(state.positions[0, guides.surfels, :2]) < 0.75, axis=1)
    moved = guides.targets - state.positions[guides.frames, guides.surfels]
    second = inner & (guides.frames == 1)
    # measured: every inner surfel guided in frame 1, median 0.012 (90th percentile 0.020) off
    # the 0.085 slide; none in frame 0, whose colours are the reference
    assert np.all(guides.frames == 1)
    assert second.sum() > 0.9 * np.all(np.abs(state.positions[1, :, :2]) < 0.75, axis=1).sum()
    assert np.median(np.linalg.norm(moved[second] - SLIDE, axis=1)) < 0.02
    assert np.abs(moved[:, 2]).max() < 1e-9  # along the surface only


def test_a_plane_of_one_colour_guides_nothing():
    _, _, guides = _slid_plane(printed=False)
    # measured: no guide at all (every shift's uncertainty infinite or far above the scale)
    assert guides is None or guides.weights.sum() < 1.0


def test_the_guides_pull_the_surfels_along_the_slide():
    state, points, guides = _slid_plane()
    topology = build_topology(state.positions, 0.3, max_stretch=None)
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    data = frame_data([points, points], normals=[normals, normals])
    noise = 0.01
    moving = np.zeros((2, state.count), dtype=bool)
    moving[1] = True  # frame 0 is held
    moved = {}
    for weight in (0.0, 1.0):
        weights = Weights(match=1 / noise**2, smooth_position=0.5 / noise**2,
                          rigid=1 / noise**2, guide=weight / noise**2)
        result = gauss_newton(
            state, topology, dataclasses.replace(data, guides=guides), weights,
            options=GaussNewtonOptions(iterations=8), free=free_unknowns(layout(state), moving),
        )
        moved[weight] = result.state.positions[1] - result.state.positions[0]
    inner = np.all(np.abs(state.positions[0, :, :2]) < 0.75, axis=1)
    # measured: without the guides nothing moves (0.0005); with them the inner surfels move
    # within 0.0073 of the slide (median 0.004), on the plane (0.0007)
    assert np.linalg.norm(moved[0.0], axis=1).max() < 0.01
    assert np.abs(moved[1.0][inner] - SLIDE).max() < 0.02
    assert np.abs(moved[1.0][:, 2]).max() < 0.01


def test_guide_data_checks_its_shapes():
    with pytest.raises(ValueError, match="one surfel"):
        GuideData(np.zeros(2, int), np.zeros(3, int), np.zeros((2, 3)), np.ones(2))
    with pytest.raises(ValueError, match="not negative"):
        GuideData(np.zeros(2, int), np.zeros(2, int), np.zeros((2, 3)), -np.ones(2))
    shifted = GuideData(np.array([0, 2]), np.array([1, 1]), np.zeros((2, 3)), np.ones(2)).shifted(1)
    assert shifted.frames.tolist() == [1, 3]


def test_carried_reference_colours_guide_a_surfel_in_every_frame():
    """The streamed run's mesh surfels keep the reference colours of the window that first saw
    them: given frame 0's colours as carried, frame 1 alone (whose own colours would be the
    reference, and guide nothing) finds the slide."""
    surfels, normals, points, point_normals = _plane(np.random.default_rng(0))
    state = surfel_state(surfels[None], normals[None])
    before, after = _print(points), _print(points - SLIDE)
    observed = np.ones((1, len(surfels)), dtype=bool)
    settings = GuideSettings(radius=3 * SPACING, scale=0.5 * SPACING)
    own = color_guides(state, observed, [points], [point_normals], [after], settings)
    assert own is None or len(own.frames) == 0
    carried = reference_colors(state, observed, [points], [point_normals], [before])
    inner = np.flatnonzero(np.all(np.abs(surfels[:, :2]) < 0.75, axis=1))
    first = len(surfels) // 2  # the first half carries its reference, the rest take their own
    guides = color_guides(
        state, observed, [points], [point_normals], [after],
        settings._replace(reference=carried[:first]),
    )
    assert guides.surfels.max() < first
    guided = np.intersect1d(guides.surfels, inner)
    assert len(guided) > 0.9 * np.sum(inner < first)
    moved = guides.targets - state.positions[0, guides.surfels]
    # measured: median 0.010 off the 0.085 slide
    assert np.median(np.linalg.norm(moved[np.isin(guides.surfels, inner)] - SLIDE, axis=1)) < 0.02
