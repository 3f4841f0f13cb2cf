"""Gauss-Newton on the surfel energy: steps descend, data alone puts surfels on a noisy plane
at the noise of their data's mean, and a rigid motion is recovered as a rigid motion."""

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from fourd.geometry.normals import estimate_normals
from fourd.geometry.rotations import procrustes
from fourd.methods.surfels import (
    AnchorData,
    GaussNewtonOptions,
    GuideData,
    MatchOptions,
    Weights,
    associate,
    build_topology,
    frame_data,
    free_unknowns,
    gauss_newton,
    layout,
    sample_surfels,
    sampling_distance,
    solve_step,
    surfel_state,
    total_energy,
)
from fourd.methods.surfels.energy import HESSIAN_PLAN
from fourd.methods.surfels.state import skew
from fourd.methods.surfels.term import PatternCache

ALL_TERMS = Weights(
    match=1.0,
    smooth_position=2.0,
    smooth_normal=0.05,
    laplace=0.2,
    rigid=3.0,
    rigid_normal=0.05,
    accel=0.5,
    accel_normal=0.01,
)


def _rotation(vector):
    angle = np.linalg.norm(vector)
    k = skew(vector / angle)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_a_step_descends_and_the_preconditioners_agree_with_a_direct_solve(random_surfel_problem):
    state, graph, data = random_surfel_problem()
    matches = associate(state, data, graph.radius)
    at = total_energy(state, graph, data, matches, ALL_TERMS)
    options = GaussNewtonOptions(cg_tolerance=1e-10, cg_iterations=5000)
    step, count = solve_step(at.hessian, at.gradient, layout(state), options)
    assert 0 < count < 5000 and at.gradient @ step < 0
    diagonal = at.hessian.diagonal()
    # the energy's Hessian is its upper triangle
    full = at.hessian + sp.triu(at.hessian, k=1).T
    direct = -sla.spsolve((full + sp.diags(options.damping * diagonal)).tocsc(), at.gradient)
    assert np.linalg.norm(step - direct) <= 1e-6 * np.linalg.norm(direct)
    jacobi, _ = solve_step(
        at.hessian,
        at.gradient,
        layout(state),
        GaussNewtonOptions(preconditioner="jacobi", cg_tolerance=1e-10, cg_iterations=5000),
    )
    assert np.linalg.norm(jacobi - direct) <= 1e-6 * np.linalg.norm(direct)
    result = gauss_newton(state, graph, data, ALL_TERMS, options=GaussNewtonOptions(iterations=1))
    assert result.energies[1] < result.energies[0]
    longer = gauss_newton(state, graph, data, ALL_TERMS, options=GaussNewtonOptions(iterations=8))
    assert np.all(np.diff(longer.energies) < 0)
    assert longer.energies[-1] < 0.9 * longer.energies[0]
    normals = np.linalg.norm(longer.state.normals, axis=-1)
    assert np.allclose(normals, 1.0, atol=1e-12)


def test_patterns_carried_between_calls_leave_the_optimisation_as_it_was(random_surfel_problem):
    # the hole filling's calls: one topology and layout, the same or other free unknowns
    state, graph, data = random_surfel_problem(seed=2)
    options = GaussNewtonOptions(iterations=3)
    carried = PatternCache()
    for chosen in (0, 1, 1):
        free = np.zeros((state.frames, state.count), dtype=bool)
        free[chosen + 1] = True
        unknowns = free_unknowns(layout(state), free)
        fresh = gauss_newton(state, graph, data, ALL_TERMS, options=options, free=unknowns)
        reused = gauss_newton(
            state, graph, data, ALL_TERMS, options=options, free=unknowns, patterns=carried
        )
        assert carried.columns == np.flatnonzero(unknowns).tobytes()
        priors = {"smooth_position", "smooth_normal", "laplace", "rigid", "accel"}
        assert {name for name, _ in carried.full} == priors
        assert set(carried.restricted) == priors | {HESSIAN_PLAN}
        # the Hessians agree to rounding (summed in another order), which the conjugate
        # gradients' tolerance (1e-6) carries into the steps
        assert np.allclose(reused.energies, fresh.energies, rtol=1e-7, atol=0.0)
        assert np.allclose(reused.state.positions, fresh.state.positions, rtol=0.0, atol=1e-6)
        assert fresh.energies[-1] < fresh.energies[0]


def test_data_alone_puts_surfels_on_the_plane_within_noise_over_root_n():
    rng = np.random.default_rng(0)
    count, noise = 3000, 0.01
    points = np.c_[rng.uniform(-1, 1, (count, 2)), rng.normal(0, noise, count)]
    sampling = sampling_distance(points, spacings=6.0)
    chosen = sample_surfels(points, sampling)
    start = points[chosen] + rng.normal(scale=0.3 * sampling, size=(len(chosen), 3))
    state = surfel_state(
        start, np.array([0.0, 0.0, 1.0]) + rng.normal(scale=0.3, size=(len(chosen), 3))
    )
    graph = build_topology(state.positions, 2 * sampling)
    data = frame_data([points], weight=1 / noise**2)
    # data only: a tangential share pins each surfel to its data's centroid
    match = MatchOptions(tangential=0.1)
    result = gauss_newton(state, graph, data, Weights(), match)
    assert result.converged and result.energies[-1] < 0.5 * result.energies[0]
    matches = associate(result.state, data, graph.radius, match)
    support = np.bincount(matches.surfels[matches.active], minlength=len(chosen))
    fitted = support >= 3
    assert fitted.mean() > 0.9
    height = result.state.positions[0, fitted, 2]
    expected = np.sqrt(np.mean(noise**2 / support[fitted]))
    # measured: rms height 1.04 times the noise of the mean of each surfel's points, the
    # largest 3.3 times
    assert np.sqrt(np.mean(height**2)) <= 1.25 * expected
    assert np.abs(height).max() <= 5 * expected


def test_a_rigid_motion_is_recovered_as_rigid():
    rng = np.random.default_rng(0)
    frames_count, count, noise = 3, 800, 0.003
    axis = np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5])
    rotations = [np.eye(3)] + [
        _rotation(axis * np.radians(4.0) * t) for t in range(1, frames_count)
    ]
    shifts = [np.array([0.02, -0.01, 0.015]) * t for t in range(frames_count)]

    def ellipsoid(n):
        p = rng.normal(size=(n, 3))
        return p / np.linalg.norm(p, axis=1, keepdims=True) * [1.0, 0.75, 0.55]

    frames = [
        ellipsoid(count) @ r.T + s + rng.normal(scale=noise, size=(count, 3))
        for r, s in zip(rotations, shifts, strict=True)
    ]
    sampling = sampling_distance(frames[0])
    chosen = sample_surfels(frames[0], sampling)
    normals = estimate_normals(frames[0]).normals[chosen]
    # every frame starts as a copy of frame 0, rotations at the identity
    state = surfel_state(
        np.repeat(frames[0][chosen][None], frames_count, 0),
        np.repeat(normals[None], frames_count, 0),
    )
    graph = build_topology(state.positions, 2 * sampling)
    normal_scale = sampling**2 / noise**2
    weights = Weights(
        rigid=1 / noise**2,
        rigid_normal=normal_scale,
        accel=0.1 / noise**2,
        smooth_normal=0.01 * normal_scale,
    )
    result = gauss_newton(
        state,
        graph,
        data := frame_data(frames, weight=1 / noise**2),
        weights,
        options=GaussNewtonOptions(cg_tolerance=1e-3),
    )
    final = result.state
    terms = total_energy(final, graph, data, associate(final, data, graph.radius), weights).terms
    i, j = graph.directed.T
    offsets = final.positions[:-1, i] - final.positions[:-1, j]
    # measured: 8.5e-6 of the rigidity energy of all offsets
    assert terms["rigid"] <= 5e-5 * weights.rigid * np.sum(offsets**2)
    for t in range(1, frames_count):
        fit = procrustes(final.positions[0], final.positions[t])
        error = np.degrees(
            np.arccos(np.clip((np.trace(fit.rotation @ rotations[t].T) - 1) / 2, -1, 1))
        )
        truth = final.positions[0] @ rotations[t].T + shifts[t]
        drift = np.linalg.norm(final.positions[t] - truth, axis=1)
        step = rotations[t] @ rotations[t - 1].T
        local = np.degrees(
            np.arccos(
                np.clip((np.einsum("sab,ab->s", final.rotations[t - 1], step) - 1) / 2, -1, 1)
            )
        )
        # measured: 0.09 / 0.14 degrees off (of 4 / 8), drift at most 1.7% of eps_sampl, 95% of
        # the local rotations within 0.25 degrees of the true increment (all within 0.82)
        assert error <= 0.5 and fit.rms <= noise
        assert drift.max() <= 0.05 * sampling
        assert np.percentile(local, 95) <= 0.75 and local.max() <= 2.0


def test_a_local_optimisation_lowers_the_whole_energy_by_what_it_reports(random_surfel_problem):
    # free surfels of one frame: the data of the other frames and the priors' rows away from
    # it are left out as constants, so the decrease it reports is the whole energy's
    state, graph, data = random_surfel_problem(seed=3, frames=4)
    moving = np.zeros((state.frames, state.count), dtype=bool)
    moving[2, ::2] = True
    free = free_unknowns(layout(state), moving)
    result = gauss_newton(
        state, graph, data, ALL_TERMS, options=GaussNewtonOptions(iterations=4), free=free
    )
    assert len(result.cg_iterations) >= 2

    def whole(at):
        return total_energy(at, graph, data, associate(at, data, graph.radius), ALL_TERMS).value

    assert result.energies[0] < 0.5 * whole(state)
    drop = whole(state) - whole(result.state)
    assert drop > 0
    assert drop == pytest.approx(result.energies[0] - result.energies[-1], rel=1e-9)
    held = ~moving
    assert np.array_equal(result.state.positions[held], state.positions[held])


def test_the_data_of_some_frames_keeps_their_points_anchors_and_guides():
    points = [np.full((k + 1, 3), float(k)) for k in range(3)]
    anchors = AnchorData(np.array([0, 1, 1]), np.zeros((3, 3)), np.ones((3, 3)), np.ones(3))
    guides = GuideData(np.array([0, 2]), np.array([4, 5]), np.zeros((2, 3)), np.ones(2))
    data = replace(frame_data(points, anchors=anchors), guides=guides)
    assert data.of_frames(np.ones(3, dtype=bool)) is data
    last = data.of_frames(np.array([False, False, True]))
    assert last.frames.tolist() == [2, 2, 2] and np.all(last.points == 2.0)
    assert last.anchors.frames.tolist() == [1, 1]
    assert last.guides.surfels.tolist() == [5]
    first = data.of_frames(np.array([True, False, False]))
    assert first.anchors.frames.tolist() == [0] and first.guides.surfels.tolist() == [4]
    assert data.of_frames(np.zeros(3, dtype=bool)).anchors is None
