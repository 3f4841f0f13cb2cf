import numpy as np
import pytest
from scipy.spatial import cKDTree

from fourd.geometry.grid import (
    Grid,
    cell_centres,
    cells_near,
    fit_grid,
    grid_points,
    occupied_cells,
    one_per_cube,
    padded_bounds,
    point_cells,
    vertices_near,
)


def _cloud(seed=0, count=400):
    rng = np.random.default_rng(seed)
    return rng.uniform([-1.0, 0.0, 2.0], [1.0, 0.5, 2.3], size=(count, 3))


def test_padded_bounds():
    points = _cloud()
    lo, hi = padded_bounds(points, 0.25)
    assert np.allclose(lo, points.min(axis=0) - 0.25)
    assert np.allclose(hi, points.max(axis=0) + 0.25)
    with pytest.raises(ValueError):
        padded_bounds(points, -1.0)


def test_fit_grid_covers_points_with_padding():
    points = _cloud()
    grid = fit_grid(points, 0.05, pad=0.1)
    assert grid.spacing == pytest.approx(0.05)
    assert np.all(grid.origin <= points.min(axis=0) - 0.1 + 1e-12)
    assert np.all(grid.upper >= points.max(axis=0) + 0.1 - 1e-12)
    # No more than one extra cell beyond the padding.
    assert np.all(grid.upper <= points.max(axis=0) + 0.1 + 0.05 + 1e-9)
    assert grid.cell_shape == tuple(n - 1 for n in grid.shape)


def test_fit_grid_default_pad_is_two_cells():
    points = _cloud()
    grid = fit_grid(points, 0.05)
    assert np.allclose(grid.origin, points.min(axis=0) - 0.1)


def test_fit_grid_caps_size_by_growing_cells():
    points = _cloud()
    grid = fit_grid(points, 0.001, max_size=32)
    assert max(grid.shape) <= 32
    assert grid.spacing > 0.001
    assert np.all(grid.origin <= points.min(axis=0))
    assert np.all(grid.upper >= points.max(axis=0))
    capped = fit_grid(points, 0.001, pad=0.2, max_size=40)
    assert max(capped.shape) <= 40
    assert np.all(capped.origin <= points.min(axis=0) - 0.2 + 1e-9)
    assert np.all(capped.upper >= points.max(axis=0) + 0.2 - 1e-9)


def test_fit_grid_margin_in_cells_grows_with_cells():
    points = _cloud()
    grid = fit_grid(points, 0.05, pad_cells=3.5)
    assert np.allclose(grid.origin, points.min(axis=0) - 3.5 * 0.05)
    capped = fit_grid(points, 0.001, pad_cells=3.5, max_size=30)
    assert max(capped.shape) <= 30
    assert np.all(capped.origin <= points.min(axis=0) - 3.5 * capped.spacing + 1e-12)
    assert np.all(capped.upper >= points.max(axis=0) + 3.5 * capped.spacing - 1e-12)
    with pytest.raises(ValueError):
        fit_grid(points, 0.05, pad_cells=5.0, max_size=10)


def test_fit_grid_scales_with_data():
    points = _cloud()
    small = fit_grid(points, 0.05)
    large = fit_grid(points * 10.0, 0.5)
    assert small.shape == large.shape
    assert np.allclose(large.origin, small.origin * 10.0)


def test_grid_points_order_and_indices():
    grid = Grid(np.array([1.0, 2.0, 3.0]), 0.5, (3, 4, 5))
    points = grid_points(grid)
    assert points.shape == (60, 3)
    flat = np.ravel_multi_index((2, 1, 3), grid.shape)
    assert np.allclose(points[flat], [2.0, 2.5, 4.5])
    assert np.allclose(grid_points(grid, np.array([flat, 0])), points[[flat, 0]])


def test_grid_validation():
    with pytest.raises(ValueError):
        Grid(np.zeros(3), 0.0, (3, 3, 3))
    with pytest.raises(ValueError):
        Grid(np.zeros(3), 1.0, (1, 3, 3))


def test_occupied_cells_hold_the_points():
    points = _cloud()
    grid = fit_grid(points, 0.07)
    mask = occupied_cells(grid, points)
    cells = point_cells(grid, points)
    assert mask.shape == grid.cell_shape
    assert mask[cells[:, 0], cells[:, 1], cells[:, 2]].all()
    assert mask.sum() == len(np.unique(cells, axis=0))
    lo = grid.origin + grid.spacing * cells
    assert np.all(points >= lo - 1e-12) and np.all(points <= lo + grid.spacing + 1e-12)


def test_cells_near_matches_brute_force():
    points = _cloud(count=150)
    grid = fit_grid(points, 0.05, pad=0.3)
    distance = 0.13
    mask = cells_near(grid, points, distance)
    all_cells = np.argwhere(np.ones(grid.cell_shape, dtype=bool))
    nearest, _ = cKDTree(points).query(cell_centres(grid, all_cells))
    expected = np.zeros(grid.cell_shape, dtype=bool)
    close = all_cells[nearest <= distance]
    expected[close[:, 0], close[:, 1], close[:, 2]] = True
    expected |= occupied_cells(grid, points)
    assert np.array_equal(mask, expected)


def test_vertices_near_matches_brute_force():
    points = _cloud(count=150)
    grid = fit_grid(points, 0.05, pad=0.3)
    distance = 0.11
    found = vertices_near(grid, points, distance)
    nearest, _ = cKDTree(points).query(grid_points(grid))
    assert np.array_equal(found, np.flatnonzero(nearest <= distance))


def test_one_per_cube_keeps_the_highest_priority_of_each_cube():
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (2000, 3))
    priority = rng.uniform(size=len(points))
    kept = one_per_cube(points, 0.5, priority)
    cubes = np.floor(points / 0.5).astype(int)
    assert len(kept) == len(np.unique(cubes, axis=0)) == 64  # every occupied cube, once
    for i in kept:
        same = np.all(cubes == cubes[i], axis=1)
        assert priority[i] == priority[same].max()
    assert np.all(np.diff(kept) > 0)
    first = one_per_cube(points, 0.5)  # no priority: the lowest index of each cube
    assert all(i == np.flatnonzero(np.all(cubes == cubes[i], axis=1))[0] for i in first)
    assert len(one_per_cube(np.zeros((0, 3)), 1.0)) == 0
