"""The rigid search per part before the alignment (beyond the paper): a small part that moved
five times ``eps_sampl`` between two scans, beyond nearest-point reach, is found and moved onto
its data; the parts already on their data stay where they are."""

import numpy as np

from fourd.methods.surfels import GaussNewtonOptions
from fourd.methods.surfels.align import align_ranges
from fourd.methods.surfels.match import MatchOptions
from fourd.methods.surfels.options import Options, energy_weights
from fourd.methods.surfels.part_search import PartSearch, part_search, surfel_parts
from fourd.methods.surfels.seeds import FramePoints, seed_model
from fourd.methods.surfels.topology import build_topology, sample_surfels

SPACING = 0.04
SAMPLING = 4 * SPACING
LIMB = np.array([1.7, 0.0, 0.0])
MOVE = np.array([0.0, 5 * SAMPLING, 0.0])


def _bumpy_ball(centre, radius, count, rng):
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    bump = 1 + 0.08 * np.sin(5 * directions[:, 0]) * np.cos(4 * directions[:, 1])
    points = centre + radius * bump[:, None] * directions
    return points, directions  # the bumps tilt the normals a little; the radial ones do here


def _scene(rng, limb_at):
    body, body_normals = _bumpy_ball(np.zeros(3), 1.0, 8000, rng)
    limb, limb_normals = _bumpy_ball(limb_at, 0.2, 400, rng)
    return np.r_[body, limb], np.r_[body_normals, limb_normals], np.r_[
        np.zeros(len(body), bool), np.ones(len(limb), bool)
    ]


def test_a_part_beyond_nearest_point_reach_is_found_and_the_rest_stays():
    rng = np.random.default_rng(0)
    points, normals, _ = _scene(rng, LIMB)
    keep = sample_surfels(points, SAMPLING)
    surfels, surfel_normals = points[keep], normals[keep]
    limb = np.linalg.norm(surfels - LIMB, axis=1) < 0.4
    topology = build_topology(surfels, 2 * SAMPLING)
    target, target_normals, _ = _scene(rng, LIMB + MOVE)
    search = PartSearch(6 * SAMPLING, SAMPLING, 6 * SAMPLING, 0.2)
    found = part_search(surfels, surfel_normals, topology, target, target_normals, search)
    shift = found.positions - surfels
    assert np.abs(shift[~limb]).max() == 0.0  # every part of the body was on its data
    assert found.moved >= 1
    # the limb's surfels went with it (a ball: its spin is free, its centre is not)
    centre = found.positions[limb].mean(axis=0) - surfels[limb].mean(axis=0)
    assert np.linalg.norm(centre - MOVE) < 0.2 * SAMPLING
    labels = surfel_parts(surfels, topology, search.size)
    assert len(np.unique(labels[limb])) == 1  # its own piece of the graph, one part


def _aligned_limb(parts):
    rng = np.random.default_rng(1)
    weights = energy_weights(Options(), SPACING, SAMPLING)
    quick = GaussNewtonOptions(iterations=5, cg_tolerance=1e-3, cg_iterations=50)
    points, normals, _ = _scene(rng, LIMB)
    left = seed_model(
        FramePoints(points, normals),
        0,
        sampling=SAMPLING,
        weights=weights,
        gauss_newton_options=quick,
        match=MatchOptions(tangential=0.05),
    )
    target, target_normals, _ = _scene(rng, LIMB + MOVE)
    aligned = align_ranges(
        left, target, target_normals, weights, quick, data_weight=1 / SPACING**2, parts=parts
    )
    before = left.state.positions[-1]
    limb = np.linalg.norm(before - LIMB, axis=1) < 0.4
    return np.linalg.norm(aligned.positions[limb].mean(0) - before[limb].mean(0) - MOVE)


def test_the_alignment_follows_the_part_the_search_found():
    search = PartSearch(6 * SAMPLING, SAMPLING, 6 * SAMPLING, 0.2)
    assert _aligned_limb(search) < 0.25 * SAMPLING  # measured: 0.04
    assert _aligned_limb(None) > SAMPLING  # nearest points alone leave it behind (measured 5.0)


def test_each_parts_offset_is_the_first_best_of_the_translation_grid():
    """:func:`part_offsets` (every translation's surfels at once, on a grid of the points)
    against the search it replaced, one k-d tree query per translation in the grid's order,
    the first best kept; a part whose points lie at a known offset finds that offset."""
    from scipy.spatial import cKDTree

    from fourd.methods.surfels.part_search import MAX_ANGLE, part_offsets

    rng = np.random.default_rng(0)
    points = rng.uniform(0, 1, (20000, 3))
    point_normals = rng.normal(size=(20000, 3))
    point_normals /= np.linalg.norm(point_normals, axis=1, keepdims=True)
    positions = rng.uniform(0.2, 0.8, (1500, 3))
    normals = rng.normal(size=(1500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    label = rng.integers(0, 7, 1500)
    tree = cKDTree(points)
    step, reach = 0.02, 0.12
    steps = int(np.floor(reach / step))
    axis = np.arange(-steps, steps + 1) * step
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    length = np.linalg.norm(grid, axis=1)
    grid = grid[np.argsort(length, kind="stable")]
    grid = grid[np.linalg.norm(grid, axis=1) <= reach + 1e-9 * step]
    best, expected = np.full(7, -1.0), np.zeros((7, 3))
    for offset in grid:
        distance, nearest = tree.query(positions + offset, distance_upper_bound=0.5 * step)
        near = np.isfinite(distance)
        near[near] = np.einsum(
            "ij,ij->i", normals[near], point_normals[nearest[near]]
        ) >= np.cos(np.radians(MAX_ANGLE))
        score = np.bincount(label, weights=near, minlength=7)
        better = score > best
        best[better], expected[better] = score[better], offset
    np.testing.assert_array_equal(part_offsets(positions, normals, label, tree, point_normals,
                                               step, reach), expected)
    # one part's surfels are the points moved back by a grid offset: that offset is its best
    shift = np.array([0.04, -0.02, 0.06])
    part = positions[label == 3]
    mine = np.r_[points, part + shift]
    found = part_offsets(part, normals[label == 3], np.zeros(len(part), dtype=np.int64),
                         cKDTree(mine), np.r_[point_normals, normals[label == 3]], step, reach)
    np.testing.assert_allclose(found[0], shift, atol=1e-12)
