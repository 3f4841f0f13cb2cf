"""The flow's low-resolution 4D implicit fit."""

from __future__ import annotations

import numpy as np
import pytest
from flow_scenes import (
    SENSORS,
    _ellipsoid_scan,
)

from fourd.geometry.neighbors import point_spacing
from fourd.methods.flow import (
    Options,
)
from fourd.methods.flow.fit import deep_inside
from fourd.methods.flow.grid import (
    build_grid,
    carve_visual_hull,
    inside_seeds,
    unsigned_distance,
)


def test_deep_inside_labels_only_far_negative_cells_of_slices_with_data():
    values = np.full((2, 12, 12, 12), -1.0)
    values[:, :, :, 9:] = 0.5  # the fit is positive on one side
    decided = np.zeros(values.shape, dtype=bool)
    decided[0, 0] = True  # a data / carved wall at x = 0 in the first slice only
    deep = deep_inside(values, decided, distance=4.0)
    assert not deep[1].any()  # nothing decided in the second slice: no distance to go by
    x = np.arange(12)[:, None, None]
    z = np.arange(12)[None, None, :]
    expected = (x >= 4) & (z < 9) & np.ones((1, 12, 1), bool)
    assert np.array_equal(deep[0], expected)
    with pytest.raises(ValueError, match="deep_inside"):
        Options(deep_inside=-1.0)


def test_offset_points_hold_the_fit_negative_inside_a_thick_ball_open_at_the_top():
    """A ball 64 cells across, never seen from above: without normals the fit's interior is
    pulled to -1 only at the few seeds and the carved cells' +1 leaks in through the unseen
    top, so the deep interior sits near zero; with the offset points one cell in along the
    normals it is clearly negative (see fourd.methods.flow.fit)."""
    from fourd.geometry.normals import estimate_normals
    from fourd.methods.flow.fit import fit_implicit

    points = _ellipsoid_scan(np.array([0.5, 0.5, 0.5]), count=20000)
    grid = build_grid(np.array([[-0.5] * 3, [0.5] * 3]), np.array([0.0]), resolution=64, substeps=1)
    spacing = point_spacing(points)
    outside = carve_visual_hull(grid, points, SENSORS, spacing=spacing, margin=1.5 * grid.h)[None]
    distance = unsigned_distance(grid, points, where=~outside[0])
    seeds = inside_seeds(distance, outside[0], minimum=1.5 * grid.h)[None]
    normals = estimate_normals(points, k=16, sensors=SENSORS).normals
    deep = np.linalg.norm(grid.centres(), axis=-1) < 0.35
    plain = fit_implicit(grid, [points], outside, seeds).values[0][deep]
    offset = fit_implicit(grid, [points], outside, seeds, normals=[normals]).values[0][deep]
    assert np.median(plain) > -0.1
    assert np.median(offset) < -0.2
    assert np.mean(offset < 0) > 0.9
    # the data stay on the zero set
    from fourd.methods.flow.fit import trilinear

    index, weight, _ = trilinear(grid, points)
    values = fit_implicit(grid, [points], outside, seeds, normals=[normals]).values[0].ravel()
    assert np.median(np.abs((values[index] * weight).sum(axis=1))) < 0.1
    with pytest.raises(ValueError, match="fit_offset"):
        Options(fit_offset=-1.0)
