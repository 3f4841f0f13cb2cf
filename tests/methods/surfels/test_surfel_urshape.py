"""The urshape (sec. 3.2): a data-free frame tied to every frame by the rigidity prior. On a
sheet folding about a hinge (isometric: two halves turning rigidly) the joint optimisation
gives an urshape with the sheet's own neighbour distances that reaches each frame by the
fold's rotations, and the mesh carried to the urshape is the result's rest."""

import numpy as np
import pytest

from fourd.methods.surfels import (
    GaussNewtonOptions,
    Urshape,
    build_topology,
    fit_urshape,
    frame_data,
    free_unknowns,
    gauss_newton,
    layout,
    surfel_mesh,
    surfel_state,
    with_urshape,
)
from fourd.methods.surfels.match import MatchOptions
from fourd.methods.surfels.motion import fit_rotations
from fourd.methods.surfels.options import Options, energy_weights

SPACING = 0.05
NOISE = 0.01


def _folding_sheet(frames=4, seed=0):
    """Surfels on a 1 x 0.6 sheet folding about x = 0 by 0, 20, 40, ... degrees: truth
    [T, S, 3], normals [T, S, 3], and data points [T, P, 3] on each frame's sheet."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(-0.5, 0.5 + 1e-9, SPACING), np.arange(0, 0.6 + 1e-9, SPACING))
    flat = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    dense = np.c_[rng.uniform(-0.5, 0.5, (3000, 2)) * [1, 0.6] + [0, 0.3], np.zeros(3000)]

    def fold(points, angle):
        out = points.copy()
        right = points[:, 0] > 0
        c, s = np.cos(angle), np.sin(angle)
        out[right, 0] = c * points[right, 0]
        out[right, 2] = s * points[right, 0]
        normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
        normals[right] = [-s, 0.0, c]
        return out, normals

    angles = np.radians(20.0 * np.arange(frames))
    truth, normals = zip(*(fold(flat, a) for a in angles), strict=True)
    data = [fold(dense, a)[0] for a in angles]
    return np.array(truth), np.array(normals), data


def _fitted(frames=3, iterations=3):
    truth, normals, data = _folding_sheet(frames)
    topology = build_topology(truth, 2.2 * SPACING, reference=0, max_stretch=None)
    state = surfel_state(truth, normals, fit_rotations(truth, topology))
    weights = energy_weights(Options(), NOISE, SPACING)
    fit = fit_urshape(
        state,
        topology,
        frame_data(data),
        weights,
        MatchOptions(tangential=0.05),
        GaussNewtonOptions(iterations=iterations, cg_tolerance=1e-3, cg_iterations=50),
    )
    return truth, normals, topology, fit


def test_a_folding_sheets_urshape_is_the_sheet_and_reaches_every_fold_by_its_rotations():
    truth, normals, topology, fit = _fitted()
    urshape = fit.urshape
    assert urshape.positions.shape == truth.shape[1:] and urshape.rotations.shape[:2] == (3, 273)
    assert fit.optimization.energies[-1] < fit.optimization.energies[0]
    i, j = topology.edges.T
    lengths = np.linalg.norm(fit.state.positions[:, i] - fit.state.positions[:, j], axis=2)
    ur_lengths = np.linalg.norm(urshape.positions[i] - urshape.positions[j], axis=1)
    # an average of the frames: its neighbour distances are nearer to every frame's (measured
    # 0.00017-0.00034, mean 0.00026) than the frames' to each other's (mean 0.00041)
    to_urshape = np.abs(ur_lengths - lengths).mean(axis=1)
    between = [np.abs(lengths[a] - lengths[b]).mean() for a in range(3) for b in range(a)]
    assert to_urshape.mean() < np.mean(between) and to_urshape.max() < 0.02 * SPACING
    # the right half's rotations from the urshape are the fold's, up to the urshape's own tilt
    right = truth[0, :, 0] > 2 * SPACING
    for t, angle in enumerate(np.radians([0.0, 20.0, 40.0])):
        relative = fit.urshape.rotations[t, right] @ fit.urshape.rotations[0, right].swapaxes(1, 2)
        turned = np.degrees(np.arccos(np.clip((np.trace(relative, axis1=1, axis2=2) - 1) / 2, -1, 1)))
        assert np.median(np.abs(turned - np.degrees(angle))) < 2.0
    # the trajectories stay on their frames' sheets
    along = np.einsum("tsa,tsa->ts", fit.state.positions - truth, normals)
    assert np.abs(along).mean() < 0.2 * NOISE
    # their rotations between frames are the urshape's composed
    composed = fit.urshape.rotations[1] @ fit.urshape.rotations[0].swapaxes(1, 2)
    assert np.allclose(fit.state.rotations[0], composed)


def test_the_mesh_is_carried_to_the_urshape_as_its_rest():
    truth, normals, topology, fit = _fitted(frames=2, iterations=1)
    plain = surfel_mesh(fit.state, SPACING)
    carried = surfel_mesh(fit.state, SPACING, urshape=fit.urshape)
    assert np.array_equal(carried.faces, plain.faces)
    assert np.allclose(carried.vertices, plain.vertices, atol=1e-9)
    assert not np.allclose(carried.rest, plain.rest, atol=1e-4)
    # the rest is the urshape's surface: as far from its surfels as frame 0's mesh from its own
    nearest = np.min(np.linalg.norm(carried.rest[:, None] - fit.urshape.positions[None], axis=2), axis=1)
    own = np.min(np.linalg.norm(plain.rest[:, None] - fit.state.positions[0][None], axis=2), axis=1)
    assert np.median(nearest) < 1.5 * np.median(own)
    one_frame = Urshape(fit.urshape.positions, fit.urshape.normals, fit.urshape.rotations[:1])
    with pytest.raises(ValueError, match="reaches 1 frames"):
        with_urshape(fit.state, one_frame)


def test_an_urshape_fitted_alone_leaves_the_trajectories_as_they_were():
    truth, normals, data = _folding_sheet(3)
    topology = build_topology(truth, 2.2 * SPACING, reference=0, max_stretch=None)
    state = surfel_state(truth, normals, fit_rotations(truth, topology))
    fit = fit_urshape(
        state,
        topology,
        frame_data(data),
        energy_weights(Options(), NOISE, SPACING),
        MatchOptions(tangential=0.05),
        GaussNewtonOptions(iterations=2, cg_tolerance=1e-3, cg_iterations=50),
        joint=False,
    )
    assert fit.state is state
    assert fit.optimization.energies[-1] < fit.optimization.energies[0]
    right = truth[0, :, 0] > 2 * SPACING
    relative = fit.urshape.rotations[2, right] @ fit.urshape.rotations[0, right].swapaxes(1, 2)
    turned = np.degrees(np.arccos(np.clip((np.trace(relative, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert np.median(np.abs(turned - 40.0)) < 2.0


def test_an_urshape_fitted_alone_is_the_one_the_data_would_give():
    """Held trajectories make the data and acceleration constants, which the fit leaves out:
    the steps are those of the whole energy."""
    truth, normals, data = _folding_sheet(3)
    topology = build_topology(truth, 2.2 * SPACING, reference=0, max_stretch=None)
    state = surfel_state(truth, normals, fit_rotations(truth, topology))
    weights = energy_weights(Options(), NOISE, SPACING)
    match = MatchOptions(tangential=0.05)
    options = GaussNewtonOptions(iterations=2, cg_tolerance=1e-3, cg_iterations=50)
    fit = fit_urshape(
        state, topology, frame_data(data), weights, match, options, joint=False
    )
    joined = with_urshape(state, Urshape(truth[0], normals[0], np.zeros((3, 273, 3, 3))))
    joined = surfel_state(
        joined.positions, joined.normals, fit_rotations(joined.positions, topology, urshape=True)
    )
    surfels = np.zeros((4, 273), dtype=bool)
    surfels[0] = True
    free = free_unknowns(layout(joined), surfels, np.ones((3, 273), dtype=bool))
    shifted = frame_data([np.zeros((0, 3))] + list(data))
    whole = gauss_newton(
        joined, topology, shifted, weights, match, options, free=free, urshape=True
    )
    assert len(whole.cg_iterations) == len(fit.optimization.cg_iterations) == 2
    assert np.allclose(fit.urshape.positions, whole.state.positions[0], atol=1e-9 * SPACING)
    assert np.allclose(fit.urshape.rotations, whole.state.rotations, atol=1e-9)
    # the data's share is a constant: the two energies differ by it alone
    assert np.ptp(whole.energies - fit.optimization.energies) < 1e-9 * whole.energies[0]
