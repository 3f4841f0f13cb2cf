import numpy as np
import pytest

from fourd.geometry.grid import fit_grid, grid_points
from fourd.geometry.implicit import imls_grid, imls_values
from fourd.geometry.marching import marching_cubes


def _plane(spacing=0.05, extent=1.0):
    axis = np.arange(-extent, extent + 1e-9, spacing)
    x, y = np.meshgrid(axis, axis, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    return points, normals


def _sphere(count=4000, radius=1.0):
    index = np.arange(count) + 0.5
    phi = np.arccos(1 - 2 * index / count)
    theta = np.pi * (1 + 5**0.5) * index
    normals = np.stack(
        [np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1
    )
    return radius * normals, normals


def test_plane_value_is_signed_height():
    points, normals = _plane()
    rng = np.random.default_rng(0)
    query = np.column_stack([rng.uniform(-0.5, 0.5, (200, 2)), rng.uniform(-0.15, 0.15, 200)])
    values = imls_values(query, points, normals, bandwidth=0.1)
    assert np.all(np.isfinite(values))
    assert np.abs(values - query[:, 2]).max() < 1e-9


def test_values_beyond_support_are_nan():
    points, normals = _plane()
    values = imls_values(
        np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 0.1]]), points, normals, bandwidth=0.1, support=0.2
    )
    assert np.isnan(values[0]) and np.isfinite(values[1])


def test_grid_matches_pointwise_evaluation():
    points, normals = _sphere(800)
    grid = fit_grid(points, 0.1, pad=0.2)
    field = imls_grid(points, normals, grid, bandwidth=0.12, support=0.3)
    expected = imls_values(grid_points(grid), points, normals, bandwidth=0.12, support=0.3)
    finite = np.isfinite(expected)
    assert np.array_equal(np.isfinite(field.values.ravel()), finite)
    assert np.allclose(field.values.ravel()[finite], expected[finite], atol=1e-9)
    assert np.all(field.distance.ravel()[finite] <= 0.3 + 1e-12)
    assert np.all(np.isinf(field.distance.ravel()[~finite]))


def test_grid_weights_are_the_gaussian_sums():
    # the splatting computes the weights along each grid row by a recurrence, not one exp each
    points, normals = _sphere(300)
    grid = fit_grid(points, 0.1, pad=0.2)
    field = imls_grid(points, normals, grid, bandwidth=0.12, support=0.3, agreement=-1.0)
    query = grid_points(grid)
    d2 = ((query[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    expected = np.where(d2 <= 0.3**2, np.exp(-d2 / 0.12**2), 0.0).sum(axis=1)
    weight = field.weight.ravel()
    assert np.array_equal(weight > 0, expected > 0)
    inside = expected > 0
    assert np.abs(weight[inside] / expected[inside] - 1.0).max() < 1e-12


def test_sphere_zero_set_lies_on_sphere():
    points, normals = _sphere(4000)
    spacing = 0.056  # about the nearest-neighbour distance of 4000 points on the unit sphere
    grid = fit_grid(points, spacing, pad=3 * spacing)
    field = imls_grid(points, normals, grid, bandwidth=2 * spacing)
    assert np.nanmax(field.values) > 0 > np.nanmin(field.values)
    values = np.where(np.isfinite(field.values), field.values, 1.0)
    near = field.distance < 2 * spacing
    cells = near[:-1, :-1, :-1] & near[1:, 1:, 1:]
    vertices, faces = marching_cubes(
        values, origin=grid.origin, spacing=grid.spacing, cell_mask=cells
    )
    radius = np.linalg.norm(vertices, axis=1)
    # Constant-fit IMLS shrinks convex shapes by about h^2 / (2 R); plus marching-cubes error.
    assert np.abs(radius - 1.0).max() < 0.02
    assert len(faces) > 1000
    # Outward gradient: inside negative.
    assert imls_values(np.zeros((1, 3)) + [0, 0, 0.9], points, normals, bandwidth=0.1)[0] < 0


def test_agreement_keeps_thin_sheets_apart():
    top, up = _plane(0.05, 0.6)
    bottom = top.copy()
    top[:, 2] = 0.05
    bottom[:, 2] = -0.05
    points = np.concatenate([top, bottom])
    normals = np.concatenate([up, -up])
    query = np.array([[0.0, 0.0, 0.06], [0.0, 0.0, -0.06], [0.0, 0.0, 0.0]])
    guarded = imls_values(query, points, normals, bandwidth=0.1)
    assert guarded[0] == pytest.approx(0.01, abs=1e-6)
    assert guarded[1] == pytest.approx(0.01, abs=1e-6)
    unguarded = imls_values(query, points, normals, bandwidth=0.1, agreement=-1.0)
    assert guarded[2] == pytest.approx(-0.05, abs=1e-6)
    # Without the guard the far sheet pulls the value: a point outside reads as inside.
    assert unguarded[0] < 0


def test_validation():
    points, normals = _plane()
    with pytest.raises(ValueError):
        imls_values(points[:3], points, normals[:5], bandwidth=0.1)
    with pytest.raises(ValueError):
        imls_values(points[:3], points, normals, bandwidth=0.0)
