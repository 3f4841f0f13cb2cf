"""The flow's space-time grid: visual hull, distances, speed bound, substeps.

(``test_flow_grid.py``: ``tests/geometry/test_grid.py`` has the plain name.)
"""

from __future__ import annotations

import numpy as np
from flow_scenes import (
    SENSORS,
    _ellipsoid_scan,
)

from fourd.geometry.neighbors import point_spacing
from fourd.methods.flow.grid import (
    build_grid,
    carve_visual_hull,
    inside_seeds,
    speed_prune,
    unsigned_distance,
)


def test_visual_hull_carves_outside_keeps_inside():
    points = _ellipsoid_scan(np.array([0.5, 0.5, 0.5]), hole=False)
    grid = build_grid(np.array([[-0.5] * 3, [0.5] * 3]), np.array([0.0]), resolution=16, substeps=1)
    sensors = np.vstack([SENSORS, [[0.0, 3.0, 0.0]]])
    carved = carve_visual_hull(
        grid, points, sensors, spacing=point_spacing(points), margin=1.5 * grid.h
    )
    centres = grid.centres()
    radius = np.linalg.norm(centres, axis=-1)
    assert not carved[radius < 0.4].any()
    assert carved[radius > 0.75].mean() > 0.95


def test_visual_hull_with_a_rim_is_tight_above_a_grazing_top():
    """Cameras slightly above a ball see its top at a grazing angle. The flow's hull leaves
    about three cells above it; with ``rim=1`` (the hull that trims the output) no more than
    the margin and about a cell, and never a cell of the ball."""
    rng = np.random.default_rng(1)
    angles = 0.3 + 2 * np.pi * np.arange(3) / 3
    sensors = np.stack([4 * np.cos(angles), np.full(3, 1.0), 4 * np.sin(angles)], axis=1)
    unit = rng.normal(size=(30000, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    points = 0.5 * unit
    seen = np.zeros(len(points), bool)
    for sensor in sensors:
        seen |= np.einsum("ij,ij->i", unit, sensor - points) > 0
    points = points[seen][:8000]
    grid = build_grid(np.array([[-0.5] * 3, [0.5] * 3]), np.array([0.0]), resolution=24, substeps=1)
    margin = 1.5 * grid.h
    centres = grid.centres()
    radius = np.linalg.norm(centres, axis=-1)
    above = (centres[..., 1] > 0.3) & (radius > 0.5 + margin + 1.5 * grid.h)
    spacing = point_spacing(points)
    wide = carve_visual_hull(grid, points, sensors, spacing=spacing, margin=margin)
    tight = carve_visual_hull(grid, points, sensors, spacing=spacing, margin=margin, rim=1)
    assert not wide[radius < 0.5].any() and not tight[radius < 0.5 - 0.5 * grid.h].any()
    assert (wide <= tight).all()
    assert tight[above].all() and not wide[above].all()


def test_distance_inside_the_hull_only_gives_the_same_seeds():
    """The hull's seeds need the distance to the data only at the cells not carved: computed
    there alone it equals the full one, and the seeds (the sphere's centre) are the same."""
    points = _ellipsoid_scan(np.array([0.4, 0.4, 0.4]), hole=False)
    grid = build_grid(np.array([[-0.5] * 3, [0.5] * 3]), np.array([0.0]), resolution=16, substeps=1)
    outside = np.linalg.norm(grid.centres(), axis=-1) > 0.42
    full = unsigned_distance(grid, points)
    inside = unsigned_distance(grid, points, where=~outside)
    assert np.array_equal(inside[~outside], full[~outside]) and np.isinf(inside[outside]).all()
    seeds = inside_seeds(inside, outside, minimum=1.5 * grid.h)
    assert seeds.any() and np.array_equal(seeds, inside_seeds(full, outside, minimum=1.5 * grid.h))
    assert np.linalg.norm(grid.centres()[seeds], axis=-1).max() < 2 * grid.h


def test_speed_prune_bounded_speed():
    alive = np.zeros((3, 9, 9, 9), bool)
    alive[0, 4, 4, 4] = True
    alive[1] = True
    alive[2] = True
    pruned = speed_prune(alive, full=False)
    assert pruned[1].sum() == 7 and pruned[2].sum() == 25


def test_frame_motion_and_automatic_substeps():
    from fourd.methods.flow.grid import frame_motion, substeps_for_motion

    rng = np.random.default_rng(0)
    base = rng.uniform(-1, 1, size=(4000, 3))
    base /= np.linalg.norm(base, axis=1, keepdims=True)
    # a unit sphere growing by 0.05, then 0.2 per frame, then a frame without points
    frames = [base, 1.05 * base, 1.25 * base, None]
    motion = frame_motion(frames)
    assert np.allclose(motion[:2], [0.05, 0.2], rtol=0.05) and np.isnan(motion[2])
    assert substeps_for_motion(motion, 0.1, limit=1.0, most=4) == 2
    assert substeps_for_motion(motion, 0.01, limit=1.0, most=4) == 4
    assert substeps_for_motion(np.array([np.nan]), 0.1, limit=1.0, most=4) == 1
