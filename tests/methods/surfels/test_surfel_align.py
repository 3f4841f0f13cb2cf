"""The alignment of two ranges (sec. 3.2) starts from a rigid motion only where the surface
determines it: a squashed spheroid seen from one side is not spun about its axis by the noise,
a bumpy blob's real turn of 20 degrees is followed; a fast limb of the crane capture is
followed where the paper's percentile cutoff leaves it behind."""

import numpy as np
import pytest

from fourd.geometry.normals import estimate_normals
from fourd.methods.surfels import GaussNewtonOptions
from fourd.methods.surfels.align import align_ranges
from fourd.methods.surfels.match import MatchOptions
from fourd.methods.surfels.options import Options, energy_weights
from fourd.methods.surfels.seeds import FramePoints, seed_model

VIEW = np.array([1.0, 0.4, 0.5]) / np.linalg.norm([1.0, 0.4, 0.5])
SPACING = 0.04
SAMPLING = 4 * SPACING


def _seen_from_one_side(points, normals, rng, noise=0.004):
    keep = normals @ VIEW > 0.2
    return FramePoints(points[keep] + rng.normal(scale=noise, size=(keep.sum(), 3)), normals[keep])


def _spheroid(radii, count, rng):
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = directions * radii
    normals = points / np.square(radii)
    return _seen_from_one_side(
        points, normals / np.linalg.norm(normals, axis=1, keepdims=True), rng
    )


def _align(first, second):
    weights = energy_weights(Options(), SPACING, SAMPLING)
    quick = GaussNewtonOptions(iterations=5, cg_tolerance=1e-3, cg_iterations=50)
    left = seed_model(
        first,
        0,
        sampling=SAMPLING,
        weights=weights,
        gauss_newton_options=quick,
        match=MatchOptions(tangential=0.05),
    )
    aligned = align_ranges(
        left, second.points, second.normals, weights, quick, data_weight=1 / SPACING**2
    )
    return left.state.positions[-1], aligned.positions


@pytest.mark.parametrize("seed", [1, 3])
def test_a_squashed_spheroid_is_not_spun_about_its_axis(seed):
    # measured: a rigid start kept whatever ICP found spun these by -30 and 10 degrees
    rng = np.random.default_rng(seed)
    before, after = _align(
        _spheroid(np.array([1, 1, 0.8]), 3000, rng),
        _spheroid(np.array([1.06, 1.06, 0.72]), 6000, rng),
    )
    ring = np.hypot(before[:, 0], before[:, 1]) > 0.5
    azimuth = np.arctan2(after[ring, 1], after[ring, 0]) - np.arctan2(
        before[ring, 1], before[ring, 0]
    )
    turn = np.angle(np.exp(1j * azimuth))
    assert abs(np.degrees(np.median(turn))) < 2.0  # measured: 0.8 and 0.3


def test_a_prolate_ball_squashing_is_not_turned_on_its_side():
    # rigid ICP matches the squashed ball with the ball turned by 90 degrees (rms 0.3 times a
    # translation's): a deformation, not a turn between two frames
    rng = np.random.default_rng(0)
    before, after = _align(
        _spheroid(np.array([0.85, 0.85, 1.2]), 3000, rng),
        _spheroid(np.array([1.1, 1.1, 0.75]), 6000, rng),
    )
    top = before[:, 2] > 0.8
    assert np.median(after[top, 2]) > 0.5  # measured: 0.65; with the turned start, 0.05


def test_a_bumpy_blob_s_turn_is_followed():
    rng = np.random.default_rng(0)

    def blob(turn):
        directions = rng.normal(size=(6000, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        bump = 1.0 + 0.15 * np.sin(3 * directions[:, 0]) * np.cos(3 * directions[:, 1])
        points = directions * bump[:, None]
        normals = estimate_normals(points).normals
        normals *= np.sign(np.einsum("ij,ij->i", normals, points))[:, None]
        return _seen_from_one_side(points @ turn.T, normals @ turn.T, rng)

    angle = np.radians(20.0)
    turn = np.array(
        [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    )
    before, after = _align(blob(np.eye(3)), blob(turn))
    error = np.linalg.norm(after - before @ turn.T, axis=1)
    moved = np.linalg.norm(before @ turn.T - before, axis=1)
    # measured: 0.05 of the turn off; from a translation alone, 0.22 of it
    assert np.median(error) < 0.12 * np.median(moved)


@pytest.mark.slow
@pytest.mark.parametrize("start", [16, 28])
def test_a_fast_limb_is_followed_without_a_percentile_cutoff(start):
    """Crane frames ``start`` and ``start + 2``, scanned with the standard protocol: the
    fastest fifth of the surfels moves 3-4 ``eps_sampl``. The paper's 85th-percentile cutoff
    drops exactly their data and they stay behind (measured: their median error 0.35 and 0.47
    of the motion); without it they follow (0.13 and 0.10)."""
    from fourd import synth
    from fourd.bench import PROTOCOL
    from fourd.cache import StageCache
    from fourd.geometry.closest_point import closest_points_on_mesh
    from fourd.geometry.neighbors import point_spacing
    from fourd.methods.surfels import pipeline
    from fourd.synth.data import shared_data_dir

    if shared_data_dir() is None or not (shared_data_dir() / "crane.npz").exists():
        pytest.skip("../shared/data/crane.npz is not available")
    truth = synth.scene("crane", frames=2, seed=0, start=start, step=2)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    spacing = point_spacing(scans.frames[0].points)
    options = Options()
    sampling = options.sampling * spacing
    frames, _ = pipeline.prepare_frames(scans.frames, spacing, options, StageCache(None))
    schedule = pipeline.assembly_schedule(options, spacing, sampling)
    left = pipeline.seed_models(frames[:1], [0], sampling, schedule, options)[0]
    before = left.state.positions[0]
    (first, faces), (second, _) = truth.frame(0), truth.frame(1)
    found = closest_points_on_mesh(first, faces, before)
    target = np.einsum("sk,skd->sd", found.barycentric, second[faces[found.triangle]])
    moved = np.linalg.norm(target - before, axis=1)
    fast = moved > np.percentile(moved, 80)
    error = {}
    for percentile in (85.0, 100.0):
        aligned = align_ranges(
            left,
            frames[1].points,
            frames[1].normals,
            schedule.weights,
            schedule.align,
            data_weight=schedule.align_data,
            percentile=percentile,
        )
        error[percentile] = np.median(np.linalg.norm(aligned.positions - target, axis=1)[fast])
    assert error[100.0] < 0.2 * np.median(moved[fast])
    assert error[100.0] < 0.6 * error[85.0]
