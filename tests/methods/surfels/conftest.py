"""Shared scans for the surfel tests."""

import numpy as np
import pytest

from fourd.methods.surfels import build_topology, frame_data, surfel_state
from fourd.methods.surfels.seeds import FramePoints


def bumpy_height(x, y):
    """A surface bumpy in both directions, so a rigid slide along it is not free."""
    return 0.15 * np.sin(1.5 * x) * np.cos(1.2 * y)


@pytest.fixture
def still_bumpy_scans():
    """``scans(count, rng, noise=0.004)``: ``count`` scans (3,000 points, true normals) of
    the still surface ``scans.height`` (:func:`bumpy_height`) over [-1, 1]^2, noisy in
    height."""

    def scans(count, rng, noise=0.004):
        def scan():
            x, y = rng.uniform(-1, 1, (2, 3000))
            points = np.c_[x, y, bumpy_height(x, y) + rng.normal(scale=noise, size=3000)]
            slope_x = 0.225 * np.cos(1.5 * x) * np.cos(1.2 * y)
            slope_y = -0.18 * np.sin(1.5 * x) * np.sin(1.2 * y)
            normals = np.c_[-slope_x, -slope_y, np.ones(3000)]
            return FramePoints(points, normals / np.linalg.norm(normals, axis=1, keepdims=True))

        return [scan() for _ in range(count)]

    scans.height = bumpy_height
    return scans


@pytest.fixture
def quick_seeds():
    """``quick_seeds(frames, sampling, quick)``: the seed models of ``frames`` (scans at point
    spacing 0.02, e.g. :func:`still_bumpy_scans`' ones) at ``eps_sampl`` ``sampling``, and the
    merges' :class:`~fourd.methods.surfels.assembly.Schedule`, every optimisation with the
    Gauss-Newton options ``quick``."""
    from fourd.methods.surfels.assembly import Schedule
    from fourd.methods.surfels.match import MatchOptions
    from fourd.methods.surfels.options import Options, energy_weights
    from fourd.methods.surfels.seeds import seed_model

    def seeds(frames, sampling, quick):
        spacing = 0.02
        weights = energy_weights(Options(), spacing, sampling)
        match = MatchOptions(tangential=0.05)
        models = [
            seed_model(f, t, sampling=sampling, weights=weights, gauss_newton_options=quick, match=match)
            for t, f in enumerate(frames)
        ]
        return models, Schedule(sampling, weights, 1 / spacing**2, 1.5, quick, quick, quick, match)

    return seeds


@pytest.fixture
def random_surfel_problem():
    """``problem(seed=0, frames=3, count=60)``: a noisy surfel state of ``count`` surfels
    over ``frames`` frames around a wavy sheet, its topology (radius 0.5) and 200 noisy
    points of the sheet per frame (weight 10), as ``(state, topology, data)``."""

    def problem(seed=0, frames=3, count=60):
        rng = np.random.default_rng(seed)
        uv = rng.uniform(-1, 1, (count, 2))
        base = np.c_[uv, 0.2 * np.sin(2 * uv[:, 0])]
        positions = base + rng.normal(scale=0.03, size=(frames, count, 3))
        normals = np.array([0.0, 0.0, 1.0]) + rng.normal(scale=0.2, size=(frames, count, 3))
        state = surfel_state(positions, normals)
        graph = build_topology(positions, 0.5, max_stretch=None)
        points = [
            base[rng.integers(count, size=200)] + rng.normal(scale=0.05, size=(200, 3))
            for _ in range(frames)
        ]
        return state, graph, frame_data(points, weight=10.0)

    return problem
